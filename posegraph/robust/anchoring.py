"""Priors as between edges from a held world node, so that whatever weighs or rejects between
edges (robust kernels, graduated non-convexity, its leverage probes) treats priors alike.

A prior on X with measurement Z has r = Log(Z⁻¹ · X) and ∂r/∂δ = jr⁻¹(r). A between edge with
measurement Z from a node W held at the identity to X has r = Log(Z⁻¹ · W⁻¹ · X): the same
residual, and the same Jacobian on X (CONVENTIONS: between and prior edges). Held nodes are
removed from the linear system, so the world node adds neither variables nor fill-in.
"""

from __future__ import annotations

import numpy as np

from ..graph import EdgeSet, PoseGraph


def world_node_id(node_ids: np.ndarray) -> int:
    """An id that is not among ``node_ids``: one above the largest, or one below the smallest
    where the largest is int64's maximum."""
    largest = int(node_ids.max())
    return largest + 1 if largest < np.iinfo(np.int64).max else int(node_ids.min()) - 1


def priors_as_edges(graph: PoseGraph) -> PoseGraph:
    """A copy with one more node, the world, last and held at the identity, in which each prior
    is a between edge from the world node to its node, appended after the between edges in the
    priors' order; the copy has no priors. Its nodes before the world node are the graph's."""
    anchored = graph.copy()
    world_id = world_node_id(graph.node_ids)
    (world,) = anchored.add_nodes([world_id], graph.group.identity((1,)))
    anchored.fix([world_id])
    priors = graph.priors
    anchored.edges = graph.edges.extended(
        EdgeSet(np.full(len(priors), world), priors.i, priors.measurements, priors.information)
    )
    anchored.priors = EdgeSet.empty(graph.group)
    return anchored
