"""posegraph against gtsam Levenberg-Marquardt on the benchmark graphs, side by side.

Usage: ``python -m posegraph.benchmarks.optimizer [--repeats 3] [--rounds 2] [--budget 0.2]
[--graphs …] [--method lm|dogleg]``. With ``--method dogleg``, posegraph's dogleg runs against
gtsam's ``DoglegOptimizer`` (default parameters) instead.
Both start from the same values (the file's, or odometry where it has no vertices) on the same
graph; gtsam holds the gauge node with a σ = 1e-6 prior. The three timings of a graph take
turns, ``repeats`` runs each and more until ``budget`` seconds have passed, for ``rounds``
rounds, so that a slow spell of the machine does not fall on one of them alone. Prints a
markdown table: time in milliseconds (best of all runs), iterations, final error ½ Σ rᵀΩr, the
time ratio posegraph/gtsam, and posegraph's time per phase; then posegraph with its defaults
(``init="auto"``), initialisation included, against the same gtsam run from the file's values.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from posegraph_datasets.paths import BENCHMARK_GRAPHS, benchmark_graph, gtsam_data_dir

from ..api import optimize
from ..graph import PoseGraph
from ..io import ReadOptions, load_graph
from ..solvers import SolverOptions, Summary
from .table import MarkdownTable
from .timing import add_timing_arguments, best_run, taking_turns

METHODS = ("lm", "dogleg")
"""The methods benchmarked, each against gtsam's own: Levenberg-Marquardt and the dogleg."""
GTSAM_GRAPHS = {
    "w10000.graph": ReadOptions(),
    "sphere2500.txt": ReadOptions(),
    "w20000.txt": ReadOptions(edge2_order="g2o"),
}
"""The graphs benchmarked from gtsam's Data/, each with its read options: w20000.txt lists its
EDGE2 information in g2o's order, as gtsam's ``readG2o`` reads it."""


def benchmark_files() -> list[Path]:
    """The benchmark graphs (shared or downloaded) and ``GTSAM_GRAPHS``, where present."""
    files = [benchmark_graph(name) for name in BENCHMARK_GRAPHS]
    files = [file for file in files if file is not None]
    data = gtsam_data_dir()
    if data is not None:
        files += [data / name for name in GTSAM_GRAPHS]
    return [f for f in files if f.is_file()]


def time_gtsam(
    graph: PoseGraph, repeats: int, budget: float = 0.0, method: str = "lm"
) -> tuple[float, int, float]:
    """Best run of gtsam Levenberg-Marquardt (or with ``method`` "dogleg", its dogleg; default
    parameters) from the graph's values, over at least ``repeats`` runs and ``budget`` seconds
    (``timing.best_run``): (seconds, iterations, final error ½ Σ rᵀΩr); NaN seconds and error
    where gtsam raises (its dogleg calls MIT's system indeterminate)."""
    import gtsam

    from ..validation.gtsam_bridge import graph_to_gtsam

    factors, initial = graph_to_gtsam(graph)

    def solve(_):
        if method == "dogleg":
            optimizer = gtsam.DoglegOptimizer(factors, initial, gtsam.DoglegParams())
        else:
            optimizer = gtsam.LevenbergMarquardtOptimizer(
                factors, initial, gtsam.LevenbergMarquardtParams()
            )
        return optimizer.optimize(), optimizer

    try:
        best, (result, optimizer) = best_run(solve, repeats, budget)
    except RuntimeError:
        return math.nan, 0, math.nan
    return best, optimizer.iterations(), factors.error(result)


def time_posegraph(
    graph: PoseGraph, repeats: int, init: str, budget: float = 0.0, method: str = "lm"
) -> tuple[float, Summary]:
    """Best run of ``optimize`` with defaults but ``init`` and ``method``, over at least
    ``repeats`` runs and ``budget`` seconds: (seconds, summary of that run). ``init`` "file"
    starts from the graph's values, like gtsam; other initialisations are timed together with
    the optimisation. Each run optimises a fresh copy of the graph, made untimed."""
    options = SolverOptions(method=method)
    best, result = best_run(
        lambda copy: optimize(copy, init=init, options=options), repeats, budget, graph.copy
    )
    return best, result.summary


def gtsam_available() -> bool:
    """Whether gtsam can be imported (``pip install 'posegraph[bench]'`` adds it)."""
    try:
        import gtsam  # noqa: F401
    except ImportError:
        return False
    return True


NO_GTSAM = (math.nan, 0, math.nan)
"""gtsam's columns where it is not installed."""


def side_by_side(
    graph: PoseGraph,
    repeats: int,
    rounds: int,
    budget: float = 0.0,
    method: str = "lm",
    with_gtsam: bool = True,
) -> tuple[tuple[float, int, float], tuple[float, Summary], tuple[float, Summary]]:
    """``time_gtsam`` (unless not ``with_gtsam``: ``NO_GTSAM``), then ``time_posegraph`` from
    the graph's values and with ``init="auto"``, all with ``method``, taking turns for
    ``rounds`` rounds; the best of each: ((seconds, iterations, error), (seconds, summary),
    (seconds, summary))."""
    timings = [
        lambda: time_posegraph(graph, repeats, "file", budget, method),
        lambda: time_posegraph(graph, repeats, "auto", budget, method),
    ]
    if with_gtsam:
        timings.insert(0, lambda: time_gtsam(graph, repeats, budget, method))
    results = taking_turns(timings, rounds)
    return results if with_gtsam else (NO_GTSAM, *results)


def _number(value: float, form: str) -> str:
    """``value`` formatted, or "–" where there is none (NaN: gtsam absent or failed)."""
    return "–" if math.isnan(value) else format(value, form)


def run(
    files: list[Path],
    repeats: int,
    rounds: int = 1,
    budget: float = 0.0,
    echo: bool = False,
    method: str = "lm",
    with_gtsam: bool = True,
) -> str:
    """Benchmark every file with ``method`` ("lm" or "dogleg"), against gtsam if
    ``with_gtsam`` (its columns "–" otherwise); returns the markdown table, printing it row by
    row if ``echo``."""
    table = MarkdownTable(
        "graph | read (ms) | gtsam (ms) | gtsam iters | gtsam error | posegraph (ms) | iters "
        "| posegraph error | rel. diff | time ratio "
        "| linearize / assemble / factorize / solve (ms) "
        "| defaults: init + optimise (ms) | init | error | time ratio",
        echo,
    )
    for path in files:
        start = time.perf_counter()
        graph = load_graph(str(path), GTSAM_GRAPHS.get(path.name, ReadOptions())).graph
        read_time = time.perf_counter() - start
        (g_time, g_iters, g_error), (p_time, summary), (d_time, defaults) = side_by_side(
            graph, repeats, rounds, budget, method, with_gtsam
        )
        phases = summary.phase_times
        split = " / ".join(
            f"{1e3 * phases[k]:.2f}" for k in ("linearize", "assemble", "factorize", "solve")
        )
        difference = (summary.final_error - g_error) / g_error
        table.add(
            f"{path.name} | {1e3 * read_time:.2f} | {_number(1e3 * g_time, '.2f')} "
            f"| {g_iters if with_gtsam else '–'} | {_number(g_error, '.10g')} "
            f"| {1e3 * p_time:.2f} | {summary.num_iterations} | {summary.final_error:.10g} "
            f"| {_number(difference, '+.1e')} | {_number(p_time / g_time, '.2f')} | {split} "
            f"| {1e3 * d_time:.2f} | {defaults.initialization} | {defaults.final_error:.10g} "
            f"| {_number(d_time / g_time, '.2f')}"
        )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_timing_arguments(parser, repeats=3)
    parser.add_argument("--graphs", nargs="*", help="names (without suffix) to run; default all")
    parser.add_argument("--method", choices=METHODS, default="lm", help="posegraph's and gtsam's")
    args = parser.parse_args()
    files = benchmark_files()
    if args.graphs:
        files = [f for f in files if f.stem in args.graphs]
    if not files:
        raise SystemExit("no benchmark graphs found (../shared/datasets or gtsam's Data/)")
    run(files, args.repeats, args.rounds, args.budget, True, args.method, gtsam_available())


if __name__ == "__main__":
    main()
