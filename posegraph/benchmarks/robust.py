"""Robust estimation against injected false loop closures (issue table).

Usage: ``python -m posegraph.benchmarks.robust [--graphs intel manhattan sphere2500]``.
For each graph, outlier rate (false loops as a fraction of all loop closures) and seed: the
fraction of false loops rejected, the fraction of true loops wrongly rejected, and ATE
(SE3-aligned). Where a ground truth exists, the table gives ATE(robust) / ATE(outlier-free), both
against it. sphere2500's is gtsam's noise-free ``sphere2500_groundtruth.txt``. intel and
manhattan ship none, so each is run twice:
- "data": the file's measurements; the ATE is that of the robust solution against the
  outlier-free one (metres, no ratio);
- "resimulated": the file's edges and information with measurements drawn anew around its
  outlier-free solution, which is then the ground truth
  (``posegraph_datasets.generators.resimulate``, seed 0).
"""

from __future__ import annotations

import argparse
import time

from posegraph_datasets.generators import resimulate
from posegraph_datasets.outliers import add_false_loops, rejection_rates
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..api import optimize
from ..evaluation import evaluate
from ..graph import PoseGraph
from ..io import read_graph
from ..lie import LieGroup
from ..trajectory_io import Trajectory, as_se3
from .table import MarkdownTable


def _trajectory(graph: PoseGraph, values: LieGroup) -> Trajectory:
    return Trajectory(graph.node_ids.astype(float), as_se3(values))


def ground_truth(name: str) -> PoseGraph | None:
    """Ground-truth poses where they ship (sphere2500), else None."""
    folder = gtsam_data_dir()
    if name == "sphere2500" and folder is not None:
        return read_graph(str(folder / "sphere2500_groundtruth.txt")).graph
    return None


def cases(name: str) -> list[tuple[str, PoseGraph, Trajectory | None]]:
    """(measurements, graph, ground truth or None) for the benchmark graph ``name``."""
    graph = read_graph(str(shared_datasets_dir() / f"{name}.g2o")).graph
    truth = ground_truth(name)
    if truth is not None:
        return [("data", graph, _trajectory(truth, truth.values))]
    solution = optimize(graph.copy()).values
    simulated = resimulate(graph, solution, seed=0)
    return [("data", graph, None), ("resimulated", simulated, _trajectory(graph, solution))]


def run(names: list[str], fractions: list[float], seeds: list[int]) -> str:
    table = MarkdownTable(
        "graph | measurements | false loops | seed | false rejected | true wrongly rejected "
        "| ATE robust | ATE outlier-free | ATE vs | ratio | time (s)",
        echo=True,
    )
    for name in names:
        for label, graph, truth in cases(name):
            clean = _trajectory(graph, optimize(graph.copy()).values)
            reference = truth or clean
            ate_clean = evaluate(clean, truth).ate.rmse if truth else 0.0
            for fraction in fractions:
                for seed in seeds:
                    corrupted, false = add_false_loops(graph, fraction, seed)
                    start = time.perf_counter()
                    result = optimize(corrupted, robust="gnc")
                    elapsed = time.perf_counter() - start
                    false_rejected, true_rejected = rejection_rates(
                        corrupted, false, result.summary.rejected_edges
                    )
                    ate = evaluate(_trajectory(corrupted, result.values), reference).ate.rmse
                    ratio = f"{ate / ate_clean:.3f}" if truth else "–"
                    against = "ground truth" if truth else "outlier-free"
                    table.add(
                        f"{name} | {label} | {fraction:.0%} | {seed} | {false_rejected:.1%} "
                        f"| {true_rejected:.2%} | {ate:.4g} | {ate_clean:.4g} | {against} "
                        f"| {ratio} | {elapsed:.1f}"
                    )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="*", default=["intel", "manhattan", "sphere2500"])
    parser.add_argument("--fractions", nargs="*", type=float, default=[0.1, 0.3])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    args = parser.parse_args()
    if shared_datasets_dir() is None:
        raise SystemExit("../shared/datasets is not beside this checkout")
    run(args.graphs, args.fractions, args.seeds)


if __name__ == "__main__":
    main()
