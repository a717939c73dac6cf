"""Rows as data (``benchmarks.runner.rows``), under the name the studies in ``research/`` import them by."""

from benchmarks.runner.rows import STRUCTURE, algorithm, chain, load_rows, read_rows, resolve

__all__ = ["STRUCTURE", "algorithm", "chain", "load_rows", "read_rows", "resolve"]
