"""Robust estimation against injected false loop closures (issue table).

Usage: ``python -m posegraph.benchmarks.robust [--graphs intel manhattan sphere2500]``.
For each graph, outlier rate (false loops as a fraction of all loop closures) and seed: the
fraction of false loops rejected, the fraction of true loops wrongly rejected, and ATE
(SE3-aligned). sphere2500's ground truth is gtsam's noise-free ``sphere2500_groundtruth.txt``
composed along its odometry: there the table gives ATE(robust) / ATE(outlier-free), both
against ground truth. intel and manhattan ship no ground truth: the table gives the ATE of the
robust solution against the outlier-free solution.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from posegraph_datasets.outliers import add_false_loops
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..api import optimize, robust_mask
from ..evaluation import evaluate
from ..io import read_graph
from ..trajectory_io import Trajectory, as_se3


def _trajectory(graph, values) -> Trajectory:
    return Trajectory(graph.node_ids.astype(float), as_se3(values))


def ground_truth(name: str):
    """Ground-truth poses where they ship (sphere2500), else None."""
    folder = gtsam_data_dir()
    if name == "sphere2500" and folder is not None:
        return read_graph(str(folder / "sphere2500_groundtruth.txt")).graph
    return None


def run(names: list[str], fractions: list[float], seeds: list[int]) -> str:
    lines = [
        "| graph | false loops | seed | false rejected | true wrongly rejected | ATE robust | ATE outlier-free "
        "| ATE vs | ratio | time (s) |",
        "|" + "---|" * 10,
    ]
    print("\n".join(lines), flush=True)
    folder = shared_datasets_dir()
    for name in names:
        graph = read_graph(str(folder / f"{name}.g2o")).graph
        clean = optimize(graph.copy())
        truth = ground_truth(name)
        reference = _trajectory(truth, truth.values) if truth else _trajectory(graph, clean.values)
        ate_clean = evaluate(_trajectory(graph, clean.values), reference).ate.rmse if truth else 0.0
        for fraction in fractions:
            for seed in seeds:
                corrupted, false = add_false_loops(graph, fraction, seed)
                loops = robust_mask(corrupted, "loops")
                start = time.perf_counter()
                result = optimize(corrupted, robust="gnc")
                elapsed = time.perf_counter() - start
                rejected = np.zeros(corrupted.num_edges, dtype=bool)
                rejected[result.summary.rejected_edges] = True
                false_rejected = (rejected & false).sum() / max(false.sum(), 1)
                true_rejected = (rejected & loops & ~false).sum() / max((loops & ~false).sum(), 1)
                ate = evaluate(_trajectory(corrupted, result.values), reference).ate.rmse
                ratio = f"{ate / ate_clean:.3f}" if truth else "–"
                against = "ground truth" if truth else "outlier-free"
                lines.append(
                    f"| {name} | {fraction:.0%} | {seed} | {false_rejected:.1%} | {true_rejected:.2%} "
                    f"| {ate:.4g} | {ate_clean:.4g} | {against} | {ratio} | {elapsed:.1f} |"
                )
                print(lines[-1], flush=True)
    return "\n".join(lines)


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
