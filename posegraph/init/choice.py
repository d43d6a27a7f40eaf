"""The choice of initial values: ``initialize`` by name, and what "auto" picks."""

from __future__ import annotations

import numpy as np

from ..graph import PoseGraph, named_nodes
from ..lie import LieGroup
from ..problem.cholesky import NotPositiveDefinite
from .chordal import chordal_values, supports
from .spanning_tree import align_to_priors, spanning_tree_values

INITIALIZERS = ("auto", "file", "odometry", "spanning-tree", "chordal")
"""Names accepted by ``initialize``."""


def choose(graph: PoseGraph) -> str:
    """What ``auto`` picks: chordal relaxation when the graph has loops and its group has it
    (SE2, SE3, Sim3), else odometry composition (on a tree every initialiser gives the same values)."""
    loops = graph.num_edges - graph.num_nodes + int(graph.components().max(initial=-1)) + 1
    return "chordal" if loops > 0 and supports(graph.group) else "odometry"


def initialize(graph: PoseGraph, method: str) -> LieGroup:
    """Initial values by ``method``: "file" (the graph's values), "odometry" (compose the chain
    i → i+1, bridging breaks through other edges), "spanning-tree" (compose along the most
    informative edges), "chordal" (``posegraph.init.chordal``) or "auto" (``choose``). The gauge
    nodes (``PoseGraph.gauge_nodes``: fixed nodes, and the lowest id of each component without a
    prior) keep their values, so that a map given away from the origin stays where it is.
    Raises ``ValueError`` naming the nodes to which the measurements compose values beyond
    double precision (a Sim3 chain whose scales multiply past 1e308, say), or when chordal's
    linear systems cannot be factorised even with a ridge (information of a range beyond
    double precision)."""
    if method == "auto":
        method = choose(graph)
    if method == "file":
        return graph.values
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            values = _composed_values(graph, method)
        except NotPositiveDefinite as error:
            largest = max(np.abs(graph.edges.information).max(initial=0.0), 1.0)
            raise ValueError(
                f"the {method} initialisation's linear system is {error}: the information's"
                f" range (entries up to {largest:.3g}) is beyond double precision; the"
                " odometry initialisation composes the measurements instead"
            ) from None
        beyond = np.flatnonzero(~np.isfinite(values.as_matrix()).all(axis=(1, 2)))
    if beyond.size:
        raise ValueError(
            f"the {method} initialisation composes the measurements to values beyond double"
            f" precision at {named_nodes(graph.node_ids[beyond])}: a translation or scale too"
            " large to hold"
        )
    return values


def _composed_values(graph: PoseGraph, method: str) -> LieGroup:
    """The values of ``initialize`` by a method other than "file" and "auto"."""
    if method == "chordal":
        return align_to_priors(graph, chordal_values(graph))
    held = np.zeros(graph.num_nodes, dtype=bool)
    held[graph.gauge_nodes()] = True
    prefer = {"odometry": "odometry", "spanning-tree": "information"}.get(method)
    if prefer is None:
        raise ValueError(
            f"unknown initialisation {method!r}; choose from {', '.join(INITIALIZERS)}"
        )
    return align_to_priors(graph, spanning_tree_values(graph, known=held, prefer=prefer))
