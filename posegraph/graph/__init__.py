"""The pose graph: nodes on one group, between edges, priors and held nodes, with editing,
input checks and topology (components, gauge, odometry)."""

from .checks import (
    element_problems,
    information_problems,
    information_ranks,
    measured_dof,
    named_nodes,
    node_id_array,
    overflowing_edges,
    start_information,
)
from .components import connected_components
from .edges import EdgeSet, measurement_mask, renumbered
from .pose_graph import POSE_GROUPS, PoseGraph
from .topology import odometry_mask

__all__ = [
    "POSE_GROUPS",
    "EdgeSet",
    "PoseGraph",
    "connected_components",
    "element_problems",
    "information_problems",
    "information_ranks",
    "measured_dof",
    "measurement_mask",
    "named_nodes",
    "node_id_array",
    "odometry_mask",
    "overflowing_edges",
    "renumbered",
    "start_information",
]
