"""Building a graph one node and edge at a time, as a SLAM back end or a file loop does, against
gtsam side by side.

Usage: ``python -m posegraph.benchmarks.building [--poses 1000 10000 50000]``.
Each step adds a pose (4 × 4 matrix) and its odometry edge (4 × 4 matrix, 6 × 6 information):
``PoseGraph.add_node`` and ``add_edge``, which check each value, measurement and information
matrix; and gtsam's ``Values.insert`` and ``NonlinearFactorGraph.add`` of a ``BetweenFactorPose3``
with a Gaussian noise model from the information, which check nothing. posegraph's time
includes the first read after the loop, which joins what was added. Prints the times in
seconds, the time per step in milliseconds, their ratio, and posegraph's time for the same
graph given as arrays in two calls.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..graph import PoseGraph
from ..lie import SE3
from .table import MarkdownTable


def _steps(count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(poses, odometry, information) as numpy arrays: (count, 4, 4), (count − 1, 4, 4) and
    (count − 1, 6, 6)."""
    rng = np.random.default_rng(seed)
    poses = SE3.exp(np.cumsum(rng.normal(scale=0.1, size=(count, 6)), axis=0))
    odometry = poses[:-1].between(poses[1:])
    information = np.eye(6) * rng.uniform(10.0, 100.0, size=(count - 1, 1, 1))
    return poses.as_matrix(), odometry.as_matrix(), information


def posegraph_one_at_a_time(poses, odometry, information) -> float:
    start = time.perf_counter()
    graph = PoseGraph(SE3)
    graph.add_node(0, poses[0])
    for k in range(1, len(poses)):
        graph.add_node(k, poses[k])
        graph.add_edge(k - 1, k, odometry[k - 1], information[k - 1])
    edges, values = graph.edges, graph.values  # the first read joins the parts
    assert len(edges) == len(values) - 1
    return time.perf_counter() - start


def posegraph_at_once(poses, odometry, information) -> float:
    start = time.perf_counter()
    graph = PoseGraph(SE3)
    graph.add_nodes(np.arange(len(poses)), poses)
    graph.add_edges(np.arange(len(poses) - 1), np.arange(1, len(poses)), odometry, information)
    return time.perf_counter() - start


def gtsam_one_at_a_time(poses, odometry, information) -> float:
    import gtsam

    start = time.perf_counter()
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(0, gtsam.Pose3(poses[0]))
    for k in range(1, len(poses)):
        values.insert(k, gtsam.Pose3(poses[k]))
        noise = gtsam.noiseModel.Gaussian.Information(information[k - 1])
        graph.add(gtsam.BetweenFactorPose3(k - 1, k, gtsam.Pose3(odometry[k - 1]), noise))
    return time.perf_counter() - start


def run(counts: list[int], echo: bool = False) -> str:
    table = MarkdownTable(
        "poses | posegraph, one at a time (s) | per step (ms) | gtsam, one at a time (s) "
        "| per step (ms) | ratio | posegraph, as arrays (s)",
        echo,
    )
    for count in counts:
        steps = _steps(count)
        ours, theirs = posegraph_one_at_a_time(*steps), gtsam_one_at_a_time(*steps)
        table.add(
            f"{count} | {ours:.2f} | {1e3 * ours / count:.3f} | {theirs:.2f} "
            f"| {1e3 * theirs / count:.3f} | {ours / theirs:.1f} "
            f"| {posegraph_at_once(*steps):.3f}"
        )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, nargs="+", default=[1000, 10000, 50000])
    run(parser.parse_args().poses, echo=True)


if __name__ == "__main__":
    main()
