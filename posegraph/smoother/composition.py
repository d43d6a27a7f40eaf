"""Values for the nodes added to a smoother's graph since its last solution: composed from the
solved ones along the new edges, then refined alone, the solved nodes held."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph
from ..init.spanning_tree import align_to_priors, spanning_tree_values
from ..problem.factors import linearize_between
from ..solvers import SolverOptions, solve

LOCAL_RELATIVE_DECREASE = 1e-4
"""Tolerance of the warm start's refinement of new nodes (the full solve follows)."""
LOCAL_MAX_ITERATIONS = 10
"""Most iterations of that refinement: a start, which the full solve finishes."""
DIRECT_COMPOSITION = 64
"""At most this many new nodes, a few streamed poses, are composed one by one
(``_compose_directly``); more, as a whole new map, go along a spanning tree."""


def compose_new_nodes(graph: PoseGraph, new: np.ndarray) -> None:
    """Values for the ``new`` nodes (a mask), composed from the others (and set in the graph):
    directly where each hangs off a node with a value (``_compose_directly``: a pose or a few
    streamed into a back end), else along a spanning tree of the edges that touch them, moved
    onto their priors."""
    if _compose_directly(graph, new):
        return
    local, local_new = _local_graph(graph, new)
    solved = ~local_new
    local.set_values(align_to_priors(local, spanning_tree_values(local, known=solved)), check=False)
    graph.set_values(graph.values.set_at(np.flatnonzero(new), local.values[local_new]), check=False)


def _compose_directly(graph: PoseGraph, new: np.ndarray) -> bool:
    """Compose each new node in index order from one edge to a node that has a value by then
    (the edge from the node before it if there is one, odometry, else the first), as a spanning
    tree would along the same edges; False, and nothing set, where there are more than
    ``DIRECT_COMPOSITION`` new nodes, a new node has a prior, or one has no such edge."""
    indices = np.flatnonzero(new)
    if indices.size > DIRECT_COMPOSITION or _has_priors(graph, indices):
        return False
    edges = graph.edges
    touching = np.flatnonzero(new[edges.i] | new[edges.j])
    i, j = edges.i[touching], edges.j[touching]
    values, valued = graph.values, ~new
    for node in indices.tolist():
        forward = touching[(j == node) & valued[i]]  # Xⱼ = Xᵢ Z
        backward = touching[(i == node) & valued[j]]  # Xᵢ = Xⱼ Z⁻¹
        if forward.size:
            edge = next((e for e in forward.tolist() if edges.i[e] == node - 1), int(forward[0]))
            value = values[edges.i[edge]] @ edges.measurements[edge]
        elif backward.size:
            edge = int(backward[0])
            value = values[edges.j[edge]] @ edges.measurements[edge].inverse()
        else:
            return False
        values = values.set_at(node, value)
        valued[node] = True
    graph.set_values(values, check=False)
    return True


def _has_priors(graph: PoseGraph, nodes: np.ndarray) -> bool:
    """Whether a prior measures any of the node indices ``nodes``."""
    priors = graph.priors.i
    return bool(priors.size) and bool(np.isin(priors, nodes).any())


def _local_graph(graph: PoseGraph, new: np.ndarray) -> tuple[PoseGraph, np.ndarray]:
    """The graph of the ``new`` nodes, the nodes they touch (held) and the edges between them,
    with the new nodes' priors; and which of its nodes are new."""
    touching = new[graph.edges.i] | new[graph.edges.j]
    involved = new.copy()
    involved[graph.edges.i[touching]] = involved[graph.edges.j[touching]] = True
    local = graph.subgraph(involved, edges=touching)
    solved = ~new[involved]
    local.fixed = solved
    local.priors = local.priors.subset(~solved[local.priors.i])
    return local, ~solved


def initialize_new_nodes(graph: PoseGraph, options: SolverOptions) -> None:
    """Values for nodes added since the last solution: compose them from solved neighbours along
    a spanning tree (``compose_new_nodes``), then refine them alone (solved nodes held) over
    the edges that touch them, so that the full solve starts close to its optimum."""
    new = ~graph.initialized
    compose_new_nodes(graph, new)
    node = np.flatnonzero(new)
    if node.size == 1 and not _has_priors(graph, node):
        _refine_one(graph, int(node[0]), min(options.max_iterations, LOCAL_MAX_ITERATIONS))
        return
    local, local_new = _local_graph(graph, new)
    local_options = dataclasses.replace(
        options,
        relative_decrease=LOCAL_RELATIVE_DECREASE,
        max_iterations=min(options.max_iterations, LOCAL_MAX_ITERATIONS),
    )
    refined = solve(local, local_options)
    graph.set_values(
        graph.values.set_at(np.flatnonzero(new), refined.values[local_new]), check=False
    )


def _refine_one(graph: PoseGraph, node: int, max_iterations: int) -> None:
    """The local refinement of one new node (no prior on it), its neighbours held: Levenberg-
    Marquardt on its d × d normal equations over the edges that touch it, with the local
    solve's tolerance on the decrease reached, or promised by the Gauss-Newton model (whose
    step is then taken without linearising there); a streamed pose spared the set-up of a
    whole solve."""
    edges = graph.edges
    local = edges.subset(np.flatnonzero((edges.i == node) | (edges.j == node)))
    ends_at_i = (local.i == node)[:, None, None]
    d = graph.group.dof
    # The edges over their own nodes alone: a change of one value copies those, not every node's.
    nodes, ends = np.unique(np.concatenate([[node], local.i, local.j]), return_inverse=True)
    local = dataclasses.replace(local, i=ends[1 : len(local) + 1], j=ends[len(local) + 1 :])
    near, at = graph.values[nodes], int(ends[0])

    def linearized(value):
        values = near.set_at(at, value)
        linearization = linearize_between(values, local)
        r = linearization.residuals
        jacobian = np.where(
            ends_at_i, linearization.jacobians[..., :d], linearization.jacobians[..., d:]
        )
        weighted = local.information @ jacobian  # Ω J
        hessian = np.einsum("mai,maj->ij", jacobian, weighted)
        gradient = np.einsum("mai,ma->i", weighted, r)
        return 0.5 * float(np.einsum("ma,mab,mb->", r, local.information, r)), hessian, gradient

    value = graph.values[node]
    cost, hessian, gradient = linearized(value)
    damping, rejected = 1e-6, False
    for _ in range(max_iterations):
        damped = hessian + damping * np.diag(np.maximum(np.diag(hessian), 1e-12))
        step = np.linalg.lstsq(damped, -gradient, rcond=None)[0]
        trial = value.retract(step)
        if -(gradient @ step) - 0.5 * (step @ hessian @ step) <= LOCAL_RELATIVE_DECREASE * cost:
            # The model promises less than the tolerance: its step is the last, taken unweighed
            # where the model has not failed yet.
            value = value if rejected else trial
            break
        trial_cost, trial_hessian, trial_gradient = linearized(trial)
        if not trial_cost < cost:
            damping, rejected = 10.0 * damping, True
            continue
        decrease = cost - trial_cost
        value, cost, hessian, gradient = trial, trial_cost, trial_hessian, trial_gradient
        damping = max(damping / 10.0, 1e-12)
        if decrease <= LOCAL_RELATIVE_DECREASE * (cost + decrease):
            break
    graph.set_values(graph.values.set_at(node, value), check=False)
