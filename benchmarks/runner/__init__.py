"""The runner: suites and rows as data, one (row, env, seed) run, its executors, checkpoints and the compact runs file.

It imports nothing of ``benchmarks.reports`` or ``benchmarks.studies``; ``python -m benchmarks.run`` joins it to the
reports.
"""
