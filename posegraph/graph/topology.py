"""The graph's shape beyond its components: which edges are odometry."""

from __future__ import annotations

import numpy as np

from .pose_graph import PoseGraph


def odometry_mask(graph: PoseGraph) -> np.ndarray:
    """Edges between consecutive nodes (in the order they were added: for a file, vertex order,
    or increasing id when it has no vertex lines), in either direction."""
    return np.abs(graph.edges.j - graph.edges.i) == 1
