"""The dissertation's experiments as functions (in-process, seeded): used by `sme reproduce`,
the benchmarks and shortened in tests."""
