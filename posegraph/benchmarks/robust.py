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

With ``--fixes``, the same graphs (sphere2500's own, intel and manhattan resimulated) get pose
fixes (priors) around the truth instead, a share of them false, and robust mode covers the
priors (``run_fixes``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from posegraph_datasets.generators import resimulate
from posegraph_datasets.outliers import (
    add_false_loops,
    add_fixes,
    rejection_rates,
    without_priors,
)
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


def with_truth(name: str, graph: PoseGraph) -> tuple[str, PoseGraph, LieGroup]:
    """(measurements, graph, true poses in its node order): sphere2500's own measurements and
    gtsam's ground truth, or the graph resimulated around its outlier-free solution, which is
    then the truth."""
    truth = ground_truth(name)
    if truth is not None:
        return "data", graph, truth.values_of(graph.node_ids)
    solution = optimize(graph.copy()).values
    return "resimulated", resimulate(graph, solution, seed=0), solution


def cases(name: str) -> list[tuple[str, PoseGraph, Trajectory | None]]:
    """(measurements, graph, ground truth or None) for the benchmark graph ``name``."""
    graph = read_graph(str(shared_datasets_dir() / f"{name}.g2o")).graph
    label, measured, truth = with_truth(name, graph)
    own = [] if measured is graph else [("data", graph, None)]
    return own + [(label, measured, _trajectory(measured, truth))]


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


def run_fixes(names: list[str], fractions: list[float], seeds: list[int]) -> str:
    """Pose fixes (σ 0.5 m and 0.05 rad) on every 10th node around the true poses, a share of
    them false, with ``robust="gnc", robust_priors=True``: the share of false fixes rejected,
    of true ones wrongly rejected, and the ATE against the truth relative to the solution
    without the false fixes."""
    table = MarkdownTable(
        "graph | false fixes | seed | false rejected | true wrongly rejected | loops rejected "
        "| ATE robust | ATE without them | ratio | time (s)",
        echo=True,
    )
    for name in names:
        graph = read_graph(str(shared_datasets_dir() / f"{name}.g2o")).graph
        _, measured, truth = with_truth(name, graph)
        d, dof = graph.group.point_dim, graph.group.dof
        information = np.diag([4.0] * d + [400.0] * (dof - d))
        reference = _trajectory(measured, truth)
        for fraction in fractions:
            for seed in seeds:
                fixed, false = add_fixes(measured, truth, 10, information, fraction, seed)
                clean = without_priors(fixed, false)
                ate_clean = evaluate(_trajectory(clean, optimize(clean).values), reference)
                start = time.perf_counter()
                result = optimize(fixed, robust="gnc", robust_priors=True)
                elapsed = time.perf_counter() - start
                rejected = np.zeros(false.size, dtype=bool)
                rejected[result.summary.rejected_priors] = True
                ate = evaluate(_trajectory(fixed, result.values), reference).ate.rmse
                table.add(
                    f"{name} | {fraction:.0%} | {seed} | {rejected[false].mean():.1%} "
                    f"| {rejected[~false].mean():.2%} | {len(result.summary.rejected_edges)} "
                    f"| {ate:.4g} | {ate_clean.ate.rmse:.4g} | {ate / ate_clean.ate.rmse:.3f} "
                    f"| {elapsed:.1f}"
                )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="*", default=["intel", "manhattan", "sphere2500"])
    parser.add_argument("--fractions", nargs="*", type=float, default=[0.1, 0.3])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument(
        "--fixes", action="store_true", help="false pose fixes (priors) instead of false loops"
    )
    args = parser.parse_args()
    if shared_datasets_dir() is None:
        raise SystemExit("../shared/datasets is not beside this checkout")
    (run_fixes if args.fixes else run)(args.graphs, args.fractions, args.seeds)


if __name__ == "__main__":
    main()
