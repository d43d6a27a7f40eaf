"""Best-of-n wall-clock timing, its options, and the ``at_least`` argument type: shared by the
benchmark scripts and the ``posegraph`` command."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any, TypeVar

Output = TypeVar("Output")

BUDGET = 0.2
"""Seconds that each timing runs for at least, per round, which gives a graph solved in a
millisecond hundreds of runs. With a fixed few, the best was mostly noise: gtsam's time on
smallGrid3D was 19.3 ms as the best of 6 runs, and 12.5 ms as the best of 60."""


def best_run(
    function: Callable[[Any], Output],
    repeats: int = 3,
    budget: float = 0.0,
    setup: Callable[[], Any] = lambda: None,
) -> tuple[float, Output]:
    """The shortest wall-clock run of ``function`` in seconds, and what that run returned.

    It runs at least ``repeats`` times, and again until ``budget`` seconds have passed (see
    ``BUDGET``). ``setup()`` runs untimed before each run, and its result is ``function``'s
    argument.
    """
    best, output, runs = float("inf"), None, 0
    deadline = time.perf_counter() + budget
    while runs < repeats or time.perf_counter() < deadline:
        argument = setup()
        start = time.perf_counter()
        result = function(argument)
        elapsed = time.perf_counter() - start
        runs += 1
        if elapsed < best:
            best, output = elapsed, result
    return best, output


def taking_turns(timings: list[Callable[[], tuple]], rounds: int) -> tuple[tuple, ...]:
    """Each of ``timings`` (callables returning (seconds, …)) run in turn, for ``rounds`` rounds,
    so that a slow spell of the machine does not fall on one of them alone; the fastest result
    of each, in order."""
    turns = [tuple(timing() for timing in timings) for _ in range(rounds)]
    return tuple(min(results, key=lambda result: result[0]) for results in zip(*turns, strict=True))


def best_time(function: Callable[[], object], repeats: int = 3) -> float:
    """The shortest of ``repeats`` wall-clock runs, in seconds (the least disturbed run)."""
    return best_run(lambda _: function(), repeats)[0]


def at_least(minimum: float, kind: type = int) -> Callable[[str], Any]:
    """An argparse type: a number of ``kind`` no smaller than ``minimum``."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"not {'an integer' if kind is int else 'a number'}: {text!r}"
            ) from None
        if not value >= minimum:
            raise argparse.ArgumentTypeError(f"must be ≥ {minimum}, not {text}")
        return value

    return parse


def add_timing_arguments(parser: argparse.ArgumentParser, repeats: int) -> None:
    """``--repeats`` (default ``repeats``), ``--rounds`` and ``--budget``: the options of a
    benchmark whose timings take turns (``optimizer.side_by_side``), for the benchmark
    scripts and ``posegraph bench``."""
    parser.add_argument(
        "--repeats",
        type=at_least(1),
        default=repeats,
        help="runs per round at least (default %(default)s)",
    )
    parser.add_argument(
        "--rounds",
        type=at_least(1),
        default=2,
        help="rounds in which gtsam and posegraph take turns; the best run counts (default %(default)s)",
    )
    parser.add_argument(
        "--budget",
        type=at_least(0, float),
        default=BUDGET,
        help="seconds of runs at least, per timing and round (default %(default)s)",
    )
