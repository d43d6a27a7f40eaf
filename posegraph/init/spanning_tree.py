"""Initial values for a pose graph.

``spanning_tree_values`` composes edge measurements along a spanning tree: the odometry chain
i → i+1 where it exists, other edges only to bridge its breaks. The composition runs on all nodes
at once by pointer jumping (each round composes every node with its ancestor's offset and halves
the remaining depth), so a chain of N poses costs O(log N) batched compositions.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..graph import PoseGraph, odometry_mask
from ..graph.spanning_forest import minimum_spanning_forest, rooted
from ..lie import LieGroup
from ..trajectory.alignment import similarity_fits

_ANCHOR_WEIGHT = 1e-9  # known values hang off the virtual root first
_ODOMETRY_WEIGHT = 1.0
_OTHER_WEIGHT = 2.0
_COMPONENT_ROOT_WEIGHT = 4.0  # above every edge weight: used only where no edge reaches


def align_to_priors(graph: PoseGraph, values: LieGroup) -> LieGroup:
    """``values`` with each component that has priors but no held node moved rigidly onto them,
    Xₖ ← T Xₖ: a tree or chordal start leaves such a component at an arbitrary anchor, from
    which Levenberg-Marquardt may not reach priors far away (UTM coordinates) or turned.

    With priors weighing position at two or more distinct points, T is the weighted fit of the
    component's positions to theirs (``similarity_fits`` without scale, weights tr(Ω_tt)/d), so
    a GNSS track sets the heading. Otherwise T = Z X⁻¹ for the prior of largest tr Ω (the first
    of equals), or only the shift onto its position if it weighs nothing but position. All
    components are aligned at once.
    """
    priors = graph.priors
    if len(priors) == 0:
        return values
    group, d = graph.group, graph.group.point_dim
    labels = graph.components()
    count = int(labels.max()) + 1
    set_by_priors = graph.components_set_by_priors()
    prior_labels = labels[priors.i]
    position_weights = np.trace(priors.information[:, :d, :d], axis1=1, axis2=2) / d
    other_weights = np.trace(priors.information[:, d:, d:], axis1=1, axis2=2)
    targets = priors.measurements.translation

    placed = set_by_priors[prior_labels] & (position_weights > 0)
    highest, lowest = np.full((count, d), -np.inf), np.full((count, d), np.inf)
    np.maximum.at(highest, prior_labels[placed], targets[placed])
    np.minimum.at(lowest, prior_labels[placed], targets[placed])
    largest = np.maximum(np.abs(highest), np.abs(lowest)).max(axis=1)
    spread = np.max(highest - lowest, axis=1) > 1e-12 * largest
    fitted = placed & spread[prior_labels]
    rotation, translation, _ = similarity_fits(
        values.translation[priors.i[fitted]],
        targets[fitted],
        position_weights[fitted],
        prior_labels[fitted],
        count,
    )
    transforms = _rigid(group, rotation, translation)

    by_weight = np.lexsort(
        (np.arange(len(priors)), -(position_weights + other_weights), prior_labels)
    )
    heaviest = by_weight[np.diff(prior_labels[by_weight], prepend=-1) != 0]  # per component
    best = heaviest[set_by_priors[prior_labels[heaviest]] & ~spread[prior_labels[heaviest]]]
    value, measurement = values[priors.i[best]], priors.measurements[best]
    full = other_weights[best] > 0
    shifts = _rigid(group, np.eye(d), measurement.translation - value.translation)
    transforms = transforms.set_at(prior_labels[best[full]], (measurement @ value.inverse())[full])
    transforms = transforms.set_at(prior_labels[best[~full]], shifts[~full])

    moved = np.flatnonzero(set_by_priors[labels])
    return values.set_at(moved, transforms[labels[moved]] @ values[moved])


def _rigid(group: type[LieGroup], rotation: np.ndarray, translation: np.ndarray) -> LieGroup:
    """Elements p ↦ R p + t of ``group`` (of scale 1 for Sim3) from (…, d, d) rotations and
    (…, d) translations."""
    d = group.point_dim
    batch = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    matrix = np.zeros(batch + (d + 1, d + 1))
    matrix[..., :d, :d], matrix[..., :d, d], matrix[..., d, d] = rotation, translation, 1.0
    return group.from_matrix(matrix)


def edge_weights(graph: PoseGraph, prefer: str) -> np.ndarray:
    """Spanning-tree weights in [1, 2] (lower is preferred).

    "odometry": consecutive-node edges first. "information": the most informative edges
    first, ranked by log det Ω (any information matrix, full or diagonal).
    """
    if prefer == "odometry":
        return np.where(odometry_mask(graph), _ODOMETRY_WEIGHT, _OTHER_WEIGHT)
    if prefer == "information":
        _, log_det = np.linalg.slogdet(graph.edges.information)
        rank = np.argsort(np.argsort(-log_det, kind="stable"), kind="stable")
        return 1.0 + rank / max(rank.size, 1)
    raise ValueError(f"prefer is 'odometry' or 'information', not {prefer!r}")


@dataclasses.dataclass(frozen=True)
class SpanningTree:
    """A minimum spanning tree (``edge_weights``) under a virtual root, index n, joined to the
    known nodes and to the first node of every component without one. ``parent`` (n + 1,) is
    each node's parent (the root's is itself); each node in ``children`` hangs from its parent
    by between edge ``edge``, measured child → parent where ``reversed``."""

    parent: np.ndarray
    children: np.ndarray
    edge: np.ndarray
    reversed: np.ndarray

    def accumulated(self, offsets, combine: Callable):
        """Each node's ``offsets`` (n + 1,) combined from the root down to it, as
        ``combine(above, below)``: pointer jumping, log₂ depth steps."""
        parent = self.parent
        while True:
            grandparent = parent[parent]
            if np.array_equal(grandparent, parent):
                return offsets
            offsets = combine(offsets[parent], offsets)
            parent = grandparent


def spanning_tree(
    graph: PoseGraph, known: np.ndarray | None = None, prefer: str = "odometry"
) -> SpanningTree:
    """The minimum spanning tree of ``edge_weights`` (see ``SpanningTree``); ``known`` marks
    nodes hung from the root."""
    n = graph.num_nodes
    if graph.num_edges == 0:  # every node hangs from the root: no tree to search
        none = np.zeros(0, dtype=np.int64)
        return SpanningTree(np.full(n + 1, n), none, none, np.zeros(0, dtype=bool))
    known = np.zeros(n, dtype=bool) if known is None else np.asarray(known, dtype=bool)
    first_of_component = graph.component_roots()
    root = n
    anchors = np.concatenate([np.flatnonzero(known), first_of_component])
    anchor_weights = np.concatenate(
        [
            np.full(known.sum(), _ANCHOR_WEIGHT),
            np.full(first_of_component.size, _COMPONENT_ROOT_WEIGHT),
        ]
    )
    i = np.concatenate([graph.edges.i, anchors])
    j = np.concatenate([graph.edges.j, np.full(anchors.size, root)])
    weights = np.concatenate([edge_weights(graph, prefer), anchor_weights])
    tree = minimum_spanning_forest(n + 1, i, j, weights)
    parent, edge = rooted(n + 1, i[tree], j[tree], root)
    children = np.flatnonzero(parent[:n] != root)
    edge = tree[edge[children]]
    return SpanningTree(parent, children, edge, graph.edges.i[edge] == children)


def spanning_tree_values(
    graph: PoseGraph, known: np.ndarray | None = None, prefer: str = "odometry"
) -> LieGroup:
    """Values from composing measurements along a minimum spanning tree (``spanning_tree``).

    ``known`` marks nodes whose current values are kept; each connected component without a
    known node starts at the identity at its lowest id.
    """
    n = graph.num_nodes
    known = np.zeros(n, dtype=bool) if known is None else np.asarray(known, dtype=bool)
    tree = spanning_tree(graph, known, prefer)
    # Offsets T_v = X_parent⁻¹ X_v: a known value or the identity below the root, else the edge.
    from_root = np.flatnonzero(tree.parent[:n] == n)
    known_from_root = from_root[known[from_root]]
    measured = graph.edges.measurements[tree.edge]
    along = measured.set_at(tree.reversed, measured[tree.reversed].inverse())
    offsets = (
        graph.group.identity((n + 1,))
        .set_at(known_from_root, graph.values[known_from_root])
        .set_at(tree.children, along)
    )
    return tree.accumulated(offsets, lambda above, below: above @ below)[:n]


def compose_missing_values(graph: PoseGraph) -> None:
    """Give the nodes without a value (``PoseGraph.initialized`` false) values composed along a
    spanning tree from the nodes that have one; where none has, from each component's lowest id,
    moved onto the priors (``align_to_priors``)."""
    known = graph.initialized.copy()
    if known.all():
        return
    values = spanning_tree_values(graph, known)
    graph.set_values(values if known.any() else align_to_priors(graph, values), check=False)
