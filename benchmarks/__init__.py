"""sb3-denfac's benchmarks: one runner, suites as data, one analysis per study (map: ``benchmarks/README.md``).

Run from the repository root with ``python -m benchmarks.<module>``, e.g. ``python -m benchmarks.run --suite figure3``.
"""
