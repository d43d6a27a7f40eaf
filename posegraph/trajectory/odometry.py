"""A trajectory as a pose graph: its poses as SE3 nodes 0 … N−1, chained by odometry edges that
measure each pose from the one before (Z = Xₖ⁻¹ Xₖ₊₁)."""

from __future__ import annotations

import numpy as np

from ..graph import PoseGraph
from ..io.trajectories import Trajectory
from ..lie import SE3


def odometry_graph(trajectory: Trajectory, information: np.ndarray) -> PoseGraph:
    """The graph of ``trajectory``'s poses (node k is its k-th pose, its values the poses) and
    the edges k → k+1 measured exactly, each weighed by the (6, 6) ``information`` over
    (ρ, φ) (``posegraph.information_from_sigmas``)."""
    poses = trajectory.poses
    count = poses.batch_shape[0]
    graph = PoseGraph(SE3)
    graph.add_nodes(np.arange(count), poses)
    if count > 1:
        steps = poses[:-1].between(poses[1:])
        graph.add_edges(np.arange(count - 1), np.arange(1, count), steps, information)
    return graph
