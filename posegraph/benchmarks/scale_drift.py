"""Scale-drift correction on generated monocular sequences (issue table).

Usage: ``python -m posegraph.benchmarks.scale_drift [--plot drift.png]``. For each drift rate
and seed: ATE (SE3-aligned to ground truth, no scale fitting) of the dead-reckoning trajectory,
of SE3-only pose-graph optimisation with the same loops, and of the Sim3 correction, with the
two ratios the issue asks for.

With ``--gtsam``, each row also times the Sim3 correction (initialisation included) against gtsam
Levenberg-Marquardt (``BetweenFactorSimilarity3``) from the lifted dead-reckoning values, side by
side (``optimizer.time_gtsam``), and gives both final errors ½ Σ rᵀΩr.

With ``--false-loops 0.3``, that share of the loop closures is false instead (random Sim3 loops,
``MonocularSequence.sim3_graph_with_false_loops``, seeded by the sequence's seed; the default
lift hears them, as it would in a file): ATE of the
correction without them, in least squares with them, and with ``robust="gnc"``, and the shares
of false and true loops that GNC rejected.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from posegraph_datasets.monocular import MonocularSequence, monocular_sequence
from posegraph_datasets.outliers import rejection_rates

from ..api import optimize
from ..graph import PoseGraph
from ..sim3.scale_drift import correct_scale_drift
from .optimizer import time_gtsam
from .table import MarkdownTable
from .timing import BUDGET, best_run, taking_turns


def run(
    drifts: list[float],
    seeds: list[int],
    plot: str | None = None,
    scale_information: float | None = None,
    gtsam: bool = False,
    poses: int = 300,
) -> str:
    gtsam_columns = (
        " | posegraph (ms) | error | gtsam (ms) | gtsam iters | gtsam error | time ratio"
        if gtsam
        else ""
    )
    table = MarkdownTable(
        "drift / keyframe | seed | ATE uncorrected | ATE SE3 PGO | ATE Sim3 | uncorrected / Sim3 "
        "| SE3 / Sim3 | time (s)" + gtsam_columns
    )
    for drift, seed, sequence in _sequences(drifts, seeds, poses):
        graph = sequence.sim3_graph(scale_information)
        corrected = correct_scale_drift(graph)  # it optimises a copy (or a lift)
        se3 = optimize(sequence.se3_graph())
        before = sequence.ate(sequence.odometry.values)
        after, se3_ate = sequence.ate(corrected.poses), sequence.ate(se3.values)
        row = (
            f"{_percent(drift)} | {seed} | {before:.4g} | {se3_ate:.4g} | {after:.4g} | {before / after:.0f}× "
            f"| {se3_ate / after:.1f}× | {corrected.result.summary.total_time:.3f}"
        )
        table.add(row + (_against_gtsam(graph) if gtsam else ""))
        if plot and (drift, seed) == (drifts[0], seeds[0]):
            from ..plotting import plot_trajectories

            curves = [
                ("uncorrected", sequence.odometry.values.translation),
                ("SE3 PGO", se3.values.translation),
                ("Sim3 corrected", corrected.poses.translation),
                ("ground truth", sequence.truth.translation),
            ]
            plot_trajectories(
                curves, plot, title=f"drift {_percent(drift)}/keyframe, seed {seed}", view="top"
            )
    return str(table)


def _against_gtsam(graph: PoseGraph) -> str:
    """The best of ``correct_scale_drift`` (defaults) and of gtsam LM from the graph's values,
    taking turns for two rounds of ``timing.BUDGET`` seconds each: | posegraph (ms) | error |
    gtsam (ms) | gtsam iters | gtsam error | time ratio."""
    (ours, corrected), (theirs, iterations, their_error) = taking_turns(
        [
            lambda: best_run(lambda _: correct_scale_drift(graph), 3, BUDGET),
            lambda: time_gtsam(graph, 3, BUDGET),
        ],
        2,
    )
    return (
        f" | {1e3 * ours:.1f} | {corrected.result.summary.final_error:.8g} | {1e3 * theirs:.1f} "
        f"| {iterations} | {their_error:.8g} | {ours / theirs:.2f}"
    )


def run_false_loops(
    drifts: list[float],
    seeds: list[int],
    fraction: float,
    scale_information: float | None = None,
    poses: int = 300,
) -> str:
    """The table of ``--false-loops`` (module docstring)."""
    table = MarkdownTable(
        "drift / keyframe | seed | false loops | ATE without them | ATE least squares "
        "| ATE gnc | false rejected | true wrongly rejected | gnc time (s)"
    )
    for drift, seed, sequence in _sequences(drifts, seeds, poses):
        graph = sequence.sim3_graph(scale_information)
        corrupted, false = sequence.sim3_graph_with_false_loops(fraction, seed, scale_information)
        clean = correct_scale_drift(graph)
        plain = correct_scale_drift(corrupted)
        robust = correct_scale_drift(corrupted, robust="gnc")
        summary = robust.result.summary
        false_rejected, true_rejected = rejection_rates(corrupted, false, summary.rejected_edges)
        table.add(
            f"{_percent(drift)} | {seed} | {false.sum()} | {sequence.ate(clean.poses):.4g} "
            f"| {sequence.ate(plain.poses):.4g} | {sequence.ate(robust.poses):.4g} "
            f"| {false_rejected:.1%} | {true_rejected:.1%} | {summary.total_time:.2f}"
        )
    return str(table)


def _percent(drift: float) -> str:
    """A drift rate per keyframe as a percentage, to its significant digits (0.05%, not 0.1%)."""
    return f"{100 * drift:g}%"


def _sequences(
    drifts: list[float], seeds: list[int], poses: int
) -> Iterator[tuple[float, int, MonocularSequence]]:
    """(drift, seed, the generated monocular sequence of ``poses`` keyframes) for every drift
    and seed."""
    for drift in drifts:
        for seed in seeds:
            yield drift, seed, monocular_sequence(poses, drift=drift, seed=seed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drifts", nargs="*", type=float, default=[0.005, 0.01, 0.02])
    parser.add_argument("--poses", type=int, default=300, help="keyframes per sequence")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--plot", help="before/after figure of the first sequence")
    parser.add_argument(
        "--false-loops", type=float, default=0.0, help="share of false loop closures to add"
    )
    parser.add_argument(
        "--gtsam", action="store_true", help="time gtsam LM on the same Sim3 graphs, side by side"
    )
    parser.add_argument(
        "--scale-information",
        type=float,
        help="information on log-scale of the lifted odometry (default: lift_graph's)",
    )
    args = parser.parse_args()
    if args.false_loops > 0:
        print(
            run_false_loops(
                args.drifts, args.seeds, args.false_loops, args.scale_information, args.poses
            )
        )
    else:
        print(
            run(
                args.drifts,
                args.seeds,
                args.plot,
                args.scale_information,
                args.gtsam,
                args.poses,
            )
        )


if __name__ == "__main__":
    main()
