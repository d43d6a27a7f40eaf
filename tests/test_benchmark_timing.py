"""The benchmarks' best-of-n timing."""

from __future__ import annotations

import argparse
import itertools
import time

import pytest

from posegraph.benchmarks.timing import add_timing_arguments, best_run

SETUP = 0.05
"""Seconds each setup sleeps: a timed setup would make every run last at least this long."""


def _timed_sleeps(pauses: list[float]):
    """(function, setup, calls) for ``best_run``: the k-th run sleeps ``pauses[k]`` seconds
    and returns k; ``calls`` counts the setups."""
    calls = itertools.count()
    remaining = iter(pauses)

    def setup() -> int:
        time.sleep(SETUP)
        return next(calls)

    def function(call: int) -> int:
        time.sleep(next(remaining))
        return call

    return function, setup, calls


def test_best_run_returns_the_shortest_runs_time_and_output_without_the_setup():
    function, setup, _ = _timed_sleeps([0.02, 0.001, 0.01])
    best, output = best_run(function, repeats=3, setup=setup)
    assert output == 1
    assert 0.001 <= best < SETUP


def test_best_run_runs_at_least_repeats_times_and_until_the_budget_is_spent():
    function, setup, calls = _timed_sleeps([0.001] * 100)
    best_run(function, repeats=2, setup=setup)
    assert next(calls) == 2
    function, setup, calls = _timed_sleeps([0.001] * 100)
    start = time.perf_counter()
    best_run(function, repeats=2, budget=0.3, setup=setup)
    assert time.perf_counter() - start >= 0.3
    assert next(calls) >= 4


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--repeats", "0"], "--repeats: must be ≥ 1"),
        (["--budget", "-0.5"], "--budget: must be ≥ 0"),
    ],
)
def test_the_benchmark_scripts_refuse_what_posegraph_bench_refuses(argv, message, capsys):
    parser = argparse.ArgumentParser()
    add_timing_arguments(parser, repeats=3)
    assert parser.parse_args([]).repeats == 3
    with pytest.raises(SystemExit):
        parser.parse_args(argv)
    assert message in capsys.readouterr().err
