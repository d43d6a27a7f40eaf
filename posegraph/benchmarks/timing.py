"""Best-of-n wall-clock timing shared by the benchmark scripts."""

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


def best_time(function: Callable[[], object], repeats: int = 3) -> float:
    """The shortest of ``repeats`` wall-clock runs, in seconds (the least disturbed run)."""
    return best_run(lambda _: function(), repeats)[0]


def add_timing_arguments(parser: argparse.ArgumentParser, repeats: int) -> None:
    """``--repeats`` (default ``repeats``), ``--rounds`` and ``--budget``: the options of a
    benchmark whose timings take turns (``optimizer.side_by_side``)."""
    parser.add_argument("--repeats", type=int, default=repeats)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument(
        "--budget",
        type=float,
        default=BUDGET,
        help="seconds of runs at least, per timing and round (default %(default)s)",
    )
