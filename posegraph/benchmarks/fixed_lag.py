"""The fixed-lag Smoother against gtsam's BatchFixedLagSmoother, side by side on the same stream.

Usage: ``python -m posegraph.benchmarks.fixed_lag [--poses 1000] [--lags 10 50 200]``.
Each stream (``posegraph_datasets.generators.visual_odometry``, SE2 and SE3) arrives one pose
per call, with the edges that end at it; each smoother starts the new pose from its own last
estimate of the pose before, times the odometry, and they take turns call by call. A call
is timed from the measurements as arrays to the estimate: for posegraph adding them to the
graph and ``Smoother.optimize``; for gtsam building its factors, ``update`` and
``calculateEstimate``. Both run Levenberg-Marquardt to a relative decrease of 1e-14. The table
gives totals, the median and p99 per call, and the largest difference between the two
estimates of any pose in the window after any call (entries of the pose matrices), and of the
window's shape (its poses relative to its oldest), and each smoother's RMS position error of
its last estimate of each pose against the truth. Where the window's place in the world is
weakly determined (a long stream from one prior), gtsam's loop and posegraph's can stop at
points apart by more in absolute terms than in shape.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
from posegraph_datasets.generators import visual_odometry

from ..graph import PoseGraph
from ..lie import SE2, SE3, LieGroup
from ..smoother import Smoother
from ..solvers import SolverOptions
from .table import MarkdownTable

RELATIVE_DECREASE = 1e-14
"""Both smoothers' stopping rule: an iteration that lowers the error by at most this share."""


@dataclasses.dataclass
class Lockstep:
    """Both smoothers on one stream: each call's time, the differences between their window
    estimates after each call (``_differences``), and each pose's last estimate."""

    times: list[float]
    peer_times: list[float]
    differences: list[tuple[float, float]]
    estimates: LieGroup
    peer_estimates: LieGroup


def lockstep(full: PoseGraph, lag: int) -> Lockstep:
    """Stream ``full`` (a prior on its first pose, then poses 0, 1, … with their edges) into
    both smoothers, one pose per call."""
    import gtsam

    from ..validation.gtsam_bridge import between_factors, from_gtsam, graph_to_gtsam

    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(RELATIVE_DECREASE)
    params.setAbsoluteErrorTol(0.0)
    peer = gtsam.BatchFixedLagSmoother(float(lag - 1), params)
    group = full.group
    getter = {SE2: "atPose2", SE3: "atPose3"}[group]
    priors, _ = graph_to_gtsam(full, hold_gauge=False)
    prior_factors = gtsam.NonlinearFactorGraph()
    for k in range(full.num_edges, priors.size()):
        prior_factors.add(priors.at(k))
    graph = PoseGraph(group)
    smoother = Smoother(graph, lag=lag)
    options = SolverOptions(relative_decrease=RELATIVE_DECREASE)
    ends = np.maximum(full.edges.i, full.edges.j)
    ours, theirs, differences, estimate, last = [], [], [], None, {}
    for k in range(full.num_nodes):
        arriving = np.flatnonzero(ends == k)
        began = time.perf_counter()
        factors = between_factors(full, arriving) if k else prior_factors
        values, stamps = gtsam.Values(), gtsam.FixedLagSmootherKeyTimestampMap()
        values.insert(k, _peer_start(estimate, full, k, arriving, getter))
        stamps.insert((k, float(k)))
        peer.update(factors, values, stamps)
        estimate = peer.calculateEstimate()
        theirs.append(time.perf_counter() - began)
        began = time.perf_counter()
        _add(graph, full, k, arriving)
        smoother.optimize(options=options)
        ours.append(time.perf_counter() - began)
        window = np.arange(max(0, k - lag + 1), k + 1)
        last.update((int(n), from_gtsam(getattr(estimate, getter)(int(n)))) for n in window)
        peer_values = group.stack([last[int(n)] for n in window])
        differences.append(_differences(peer_values, graph.values[window]))
    peer_estimates = group.stack([last[n] for n in range(full.num_nodes)])
    return Lockstep(ours, theirs, differences, graph.values, peer_estimates)


def _differences(theirs: LieGroup, ours: LieGroup) -> tuple[float, float]:
    """The largest difference between two estimates of a window's poses (entries of the pose
    matrices), and the same for the poses relative to the window's oldest (its shape)."""
    absolute = np.abs(theirs.as_matrix() - ours.as_matrix()).max()
    shape = (theirs[0].inverse() @ theirs).as_matrix() - (ours[0].inverse() @ ours).as_matrix()
    return float(absolute), float(np.abs(shape).max())


def _peer_start(estimate, full: PoseGraph, k: int, arriving: np.ndarray, getter: str):
    """gtsam's start for pose k: the first pose's value, else its own estimate of the pose
    before times the odometry (the first edge arriving, from k − 1), as posegraph composes."""
    from ..validation.gtsam_bridge import to_gtsam

    if k == 0:
        return to_gtsam(full.values[0])
    return getattr(estimate, getter)(k - 1).compose(to_gtsam(full.edges.measurements[arriving[0]]))


def _add(graph: PoseGraph, full: PoseGraph, k: int, arriving: np.ndarray) -> None:
    """Add pose k (without a value but for the first), ``full``'s edges ``arriving`` and, with
    pose 0, its priors."""
    graph.add_node(k, full.values[0] if k == 0 else None)
    if k == 0:
        graph.add_priors(
            full.node_ids[full.priors.i], full.priors.measurements, full.priors.information
        )
    edges = full.edges
    graph.add_edges(
        edges.i[arriving],
        edges.j[arriving],
        edges.measurements[arriving],
        edges.information[arriving],
    )


def row(group: type[LieGroup], poses: int, lag: int, seed: int) -> str:
    """One table row: the stream, the lag, both smoothers' totals and per-call latency, their
    differences, and each one's RMS position error of its last estimates against the truth."""
    full, truth = visual_odometry(group, poses, reach=min(lag, 8), seed=seed)
    run = lockstep(full, lag)
    ours, theirs, differences = run.times, run.peer_times, run.differences
    total, peer_total = sum(ours), sum(theirs)
    cells = [
        f"{group.__name__}, {poses} poses",
        str(lag),
        f"{total:.2f} s",
        f"{peer_total:.2f} s",
        f"{total / peer_total:.2f}",
        _latency(ours),
        _latency(theirs),
        f"{max(a for a, _ in differences):.1e}",
        f"{max(s for _, s in differences):.1e}",
        f"{_rms_position_error(run.estimates, truth):.4f} / "
        f"{_rms_position_error(run.peer_estimates, truth):.4f}",
    ]
    return " | ".join(cells)


def _rms_position_error(estimates: LieGroup, truth: LieGroup) -> float:
    """RMS distance between estimated and true positions (the prior on pose 0 sets the frame)."""
    errors = estimates.as_matrix()[..., :-1, -1] - truth.as_matrix()[..., :-1, -1]
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=-1))))


def _latency(calls: list[float]) -> str:
    """Median and p99 of per-call times, in ms."""
    median, p99 = np.percentile(np.asarray(calls) * 1e3, [50, 99])
    return f"{median:.2f} / {p99:.2f}"


def main(arguments: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=1000)
    parser.add_argument("--lags", type=int, nargs="+", default=[10, 50, 200])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(arguments)
    table = MarkdownTable(
        "stream | lag | posegraph | gtsam | ratio | posegraph ms median / p99 | "
        "gtsam ms median / p99 | max difference | max shape difference | "
        "RMS position error (m) posegraph / gtsam",
        echo=True,
    )
    for group in (SE2, SE3):
        for lag in args.lags:
            table.add(row(group, args.poses, lag, args.seed))


if __name__ == "__main__":
    main()
