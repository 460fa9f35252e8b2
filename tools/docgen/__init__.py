"""Generators of the documentation's tables: parameter tables from the typed declarations
(`params_doc`) and results blocks from the benchmarks' kept output (`results_doc`)."""
