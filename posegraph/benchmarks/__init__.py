"""Benchmark scripts (run with ``python -m posegraph.benchmarks.NAME``); not timed tests."""
