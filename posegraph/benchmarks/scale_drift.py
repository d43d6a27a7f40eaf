"""Scale-drift correction on generated monocular sequences (issue table).

Usage: ``python -m posegraph.benchmarks.scale_drift [--plot drift.png]``. For each drift rate
and seed: ATE (SE3-aligned to ground truth, no scale fitting) of the dead-reckoning trajectory,
of SE3-only pose-graph optimisation with the same loops, and of the Sim3 correction, with the
two ratios the issue asks for.
"""

from __future__ import annotations

import argparse

from posegraph_datasets.monocular import monocular_sequence

from ..api import optimize
from ..scale_drift import correct_scale_drift
from .table import MarkdownTable


def run(drifts: list[float], seeds: list[int], plot: str | None = None) -> str:
    table = MarkdownTable(
        "drift / keyframe | seed | ATE uncorrected | ATE SE3 PGO | ATE Sim3 | uncorrected / Sim3 "
        "| SE3 / Sim3 | time (s)"
    )
    for drift in drifts:
        for seed in seeds:
            sequence = monocular_sequence(drift=drift, seed=seed)
            corrected = correct_scale_drift(sequence.sim3_graph())
            se3 = optimize(sequence.se3_graph())
            before = sequence.ate(sequence.odometry.values)
            after, se3_ate = sequence.ate(corrected.poses), sequence.ate(se3.values)
            table.add(
                f"{drift:.1%} | {seed} | {before:.4g} | {se3_ate:.4g} | {after:.4g} | {before / after:.0f}× "
                f"| {se3_ate / after:.1f}× | {corrected.result.summary.total_time:.3f}"
            )
            if plot and (drift, seed) == (drifts[0], seeds[0]):
                from ..plotting import plot_trajectories

                curves = [
                    ("uncorrected", sequence.odometry.values.translation),
                    ("SE3 PGO", se3.values.translation),
                    ("Sim3 corrected", corrected.poses.translation),
                    ("ground truth", sequence.truth.translation),
                ]
                plot_trajectories(
                    curves, plot, title=f"drift {drift:.1%}/keyframe, seed {seed}", view="top"
                )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drifts", nargs="*", type=float, default=[0.005, 0.01, 0.02])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--plot", help="before/after figure of the first sequence")
    args = parser.parse_args()
    print(run(args.drifts, args.seeds, args.plot))


if __name__ == "__main__":
    main()
