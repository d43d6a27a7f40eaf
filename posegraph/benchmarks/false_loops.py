"""Robust mode's acceptance table: false loops of two generators on real graphs.

Usage: ``python -m posegraph.benchmarks.false_loops [--graphs intel manhattan parking-garage
sphere2500 w10000] [--fractions 0.1 0.3] [--seeds 0 1 2] [--gtsam] [--information-scale X]``.

For each graph, generator (``project``: ``posegraph_datasets.outliers.add_false_loops``;
``anywhere``: ``add_false_loops_anywhere``), outlier rate (false loops as a fraction of all loop
closures) and seed: the share of false loops rejected, the share of true loops wrongly
rejected, the least-squares error ½ Σ rᵀΩr over the true measurements (at the file's
information) at the robust solution relative to the outlier-free optimum's, robust mode's
time, and that time over least squares' from the same start (odometry; the best of
``LEAST_SQUARES_RUNS``); whether robust mode calibrated the information. Both modes run once,
untimed, on a false-loop file of the bundled ``manhattan_small.g2o`` before the table, so that
no row's time holds the imports that a first robust solve makes. With ``--gtsam``, gtsam's GNC
(``GncLMOptimizer``, TLS, set up as posegraph's: ``robust.gtsam_gnc``) on the same graph: its
error ratio and time. With ``--information-scale``, every measurement's information is
multiplied by X first (a file that misstates its noise; the graph's name is shown with ×X);
the error ratios do not change with a uniform scale.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from posegraph_datasets import example
from posegraph_datasets.outliers import add_false_loops, add_false_loops_anywhere, rejection_rates
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..api import optimize
from ..graph import PoseGraph
from ..io import load_graph
from ..problem.factors import chi2
from .robust import gtsam_gnc
from .table import MarkdownTable
from .timing import best_time

GENERATORS = {"project": add_false_loops, "anywhere": add_false_loops_anywhere}
LEAST_SQUARES_RUNS = 3
"""Least squares' time is the best of this many runs: it takes a fraction of a second, where
the machine's noise would otherwise move the ratio by a third."""


def load(name: str) -> PoseGraph:
    """A benchmark graph: ``../shared/datasets/NAME.g2o``, or gtsam's ``Data/NAME.graph``."""
    shared = shared_datasets_dir()
    if shared is not None and (shared / f"{name}.g2o").exists():
        return load_graph(str(shared / f"{name}.g2o")).graph
    return load_graph(str(gtsam_data_dir() / f"{name}.graph")).graph


def _error(graph: PoseGraph, values) -> float:
    """½ Σ rᵀΩr of ``graph``'s measurements at ``values``."""
    return 0.5 * chi2(values, graph.edges, graph.priors)


def _row(name: str, generator: str, graph: PoseGraph, fraction: float, seed: int, gtsam: bool):
    clean_error = _error(graph, optimize(graph.copy()).values)
    make = GENERATORS[generator]
    corrupted, false = make(graph, fraction, seed)
    least_squares = best_time(
        lambda: optimize(corrupted.copy(), init="odometry"), repeats=LEAST_SQUARES_RUNS
    )
    began = time.perf_counter()
    result = optimize(corrupted.copy(), robust="gnc")
    seconds = time.perf_counter() - began
    summary = result.summary
    false_rejected, true_rejected = rejection_rates(
        corrupted, false, np.asarray(summary.rejected_edges, dtype=np.int64)
    )
    ratio = _error(graph, result.values) / clean_error
    calibrated = "yes" if summary.calibration else "no"
    cells = [
        f"{name} | {generator} | {fraction:.0%} | {seed} | {false_rejected:.2%} "
        f"| {true_rejected:.2%} | {ratio:.4f} | {seconds:.1f} | {seconds / least_squares:.1f} "
        f"| {calibrated}"
    ]
    if gtsam:
        run = gtsam_gnc(corrupted)
        cells.append(f"{_error(graph, run.values) / clean_error:.4f} | {run.seconds:.1f}")
    return " | ".join(cells)


def _warm_up() -> None:
    """Both modes once on a false-loop file of the bundled ``manhattan_small.g2o``, untimed:
    the modules that a solve imports on first use are imported then."""
    corrupted, _ = add_false_loops(load_graph(example("manhattan_small.g2o")).graph, 0.1, 0)
    optimize(corrupted.copy(), init="odometry")
    optimize(corrupted.copy(), robust="gnc")


def run(names, fractions, seeds, generators, gtsam: bool = False, scale: float = 1.0) -> str:
    header = (
        "graph | false loops | rate | seed | false rejected | true wrongly rejected "
        "| error / outlier-free | time (s) | time / least squares | calibrated"
    )
    if gtsam:
        header += " | gtsam error / outlier-free | gtsam time (s)"
    table = MarkdownTable(header, echo=True)
    _warm_up()
    for name in names:
        graph = load(name)
        if scale != 1.0:
            graph = graph.weighted(
                np.full(graph.num_edges, scale), np.full(len(graph.priors), scale)
            )
            name = f"{name} ×{scale:g}"
        for generator in generators:
            for fraction in fractions:
                for seed in seeds:
                    table.add(_row(name, generator, graph, fraction, seed, gtsam))
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--graphs",
        nargs="*",
        default=["intel", "manhattan", "parking-garage", "sphere2500", "w10000"],
    )
    parser.add_argument("--generators", nargs="*", default=list(GENERATORS), choices=GENERATORS)
    parser.add_argument("--fractions", nargs="*", type=float, default=[0.1, 0.3])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--gtsam", action="store_true", help="gtsam's GNC side by side")
    parser.add_argument(
        "--information-scale", type=float, default=1.0, help="every information times this"
    )
    args = parser.parse_args()
    if not args.information_scale > 0:
        parser.error("--information-scale must be positive")
    if shared_datasets_dir() is None:
        raise SystemExit("../shared/datasets is not beside this checkout")
    run(
        args.graphs, args.fractions, args.seeds, args.generators, args.gtsam, args.information_scale
    )


if __name__ == "__main__":
    main()
