"""The benchmarks' best-of-n timing."""

from __future__ import annotations

import argparse
import itertools

import pytest

from posegraph.benchmarks import timing
from posegraph.benchmarks.timing import add_timing_arguments, best_run

SETUP = 0.05
"""Seconds each setup takes: a timed setup would make every run last at least this long."""


class _Clock:
    """A stand-in for the ``time`` module whose clock moves only when told: the tests do not
    depend on how long the machine takes to sleep."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


def _timed_runs(monkeypatch, pauses: list[float]):
    """(function, setup, calls, clock) for ``best_run`` on a ``_Clock``: each setup takes
    ``SETUP`` seconds, the k-th run takes ``pauses[k]`` seconds and returns k, and ``calls``
    counts the setups."""
    clock = _Clock()
    monkeypatch.setattr(timing, "time", clock)
    calls = itertools.count()
    remaining = iter(pauses)

    def setup() -> int:
        clock.now += SETUP
        return next(calls)

    def function(call: int) -> int:
        clock.now += next(remaining)
        return call

    return function, setup, calls, clock


def test_best_run_returns_the_shortest_runs_time_and_output_without_the_setup(monkeypatch):
    function, setup, _, _ = _timed_runs(monkeypatch, [0.02, 0.001, 0.01])
    best, output = best_run(function, repeats=3, setup=setup)
    assert output == 1
    assert best == pytest.approx(0.001)


def test_best_run_runs_at_least_repeats_times_and_until_the_budget_is_spent(monkeypatch):
    function, setup, calls, _ = _timed_runs(monkeypatch, [0.001] * 100)
    best_run(function, repeats=2, setup=setup)
    assert next(calls) == 2
    function, setup, calls, clock = _timed_runs(monkeypatch, [0.001] * 100)
    best_run(function, repeats=2, budget=0.3, setup=setup)
    assert clock.now >= 0.3
    assert next(calls) == 6  # 0.051 s a run: the sixth ends past 0.3 s


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
