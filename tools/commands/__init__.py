"""The `sme` subcommands, one module each (`sme demo` is `demo.py`); `tools/cli.py` registers them,
`sme bench` lives with its benchmarks in `tools/bench/`."""
