"""Marginal covariances of chosen nodes, and of the relative poses of node pairs, from the sparse
factorisation of the information matrix.

At the estimate X̂, the Gaussian approximation of the posterior has information H = Σ Jᵀ Ω J over
the free nodes' tangents, with right perturbation X = X̂ · Exp(δ) (CONVENTIONS.md). The
covariance blocks of chosen nodes are blocks of H⁻¹, obtained from one sparse Cholesky
factorisation (never a dense inverse): by solves with the nodes' unit columns, or with CHOLMOD
for more than a few nodes (``problem.cholesky.SOLVED_COLUMNS``), by selected inversion of the
factor on the paths from those nodes to the root of its elimination tree. A joint covariance
of up to ``COUPLED_COLUMNS`` columns puts the blocks between its nodes into H's pattern (as
zeros), so that they lie in the factor's; a larger one comes from solves. Held nodes (the
gauge) have zero covariance: everything is relative to them, as in gtsam with a tight prior on
the gauge node. A relative pose's covariance is its pair's joint covariance mapped through the
derivative of Xᵢ⁻¹Xⱼ; it does not depend on the gauge.
"""

from __future__ import annotations

import numpy as np

from ..graph import PoseGraph
from ..lie import LieGroup
from ..problem.cholesky import NotPositiveDefinite, covariance_by_solves
from ..problem.covariance import joint_covariances
from ..problem.information import factorize_information, factorized_information
from ..problem.linear import NormalEquations
from ..problem.observability import SINGULAR, singular_information, undetermined_direction
from ..smoother import Smoother


def marginals(
    source: Smoother | PoseGraph,
    nodes,
    values: LieGroup | None = None,
    joint: bool = False,
    linear_solver: str = "auto",
    require_measured: bool = False,
) -> np.ndarray:
    """Covariances of ``nodes`` (ids) of a ``Smoother``'s graph, or of a graph, at ``values``
    (default: the graph's current values, which ``optimize`` leaves at the optimum).

    Given a smoother, each between edge's (and prior's) information counts with its weight in
    its last solution (``Smoother.weights``: IRLS weights ρ′(s), as gtsam's robust noise models
    weigh it; measurements rejected as outliers not at all), so a false loop closure or a false
    fix cannot shrink the covariances; and while the graph's structure is unchanged since its
    last least-squares solve, the covariances of a few nodes refill that solve's normal
    equations instead of building new ones, and at its solution factorise the H it assembled
    there (``Smoother.current_normal_matrix``). Given a graph alone, every measurement counts
    in full.

    Returns (k, d, d) marginal blocks, or with ``joint=True`` the (k·d, k·d) joint covariance of
    the nodes together (for a pair, the 2d × 2d matrix with their cross-covariance). Raises
    ``NotPositiveDefinite`` if the information matrix is singular, or is to working precision
    (a pivot of at most ``observability.SINGULAR`` of its diagonal entry, where the blocks
    would keep fewer than four digits: a graph that SuperLU factorised with a pivot share of
    8e-16 gave blocks with eigenvalues −8e13 and 2e14), naming the nodes with
    directions that no measurement reaches (``posegraph.problem.observability``), if any. With
    ``require_measured``, such directions are refused even where H factorises (away from zero
    residuals it can, and gives them covariances that mean nothing), also those that move
    several nodes together (``observability.undetermined_direction``: a map that can turn about
    the position-only edges that join it to the rest), at the cost of one more factorisation.
    """
    graph = source.graph if isinstance(source, Smoother) else source
    index = graph.index(nodes)
    groups = index[None, :] if joint else index[:, None]
    values = _values(graph, values)
    covariances = _group_covariances(source, groups, values, linear_solver, require_measured)
    return covariances[0] if joint else covariances


def relative_covariances(
    source: Smoother | PoseGraph,
    i_ids,
    j_ids,
    values: LieGroup | None = None,
    linear_solver: str = "auto",
    require_measured: bool = False,
) -> np.ndarray:
    """Covariances (k, d, d) of the relative poses Xᵢ⁻¹ Xⱼ of k node pairs (ids), over the
    tangent δ of Ẑ · Exp(δ), Ẑ = X̂ᵢ⁻¹ X̂ⱼ at ``values`` (right perturbation, CONVENTIONS.md):
    what a loop-closure search gates a candidate pair by.

    From Xᵢ⁻¹ Xⱼ = Exp(−δᵢ) Ẑ Exp(δⱼ) = Ẑ Exp(−Ad(Ẑ⁻¹) δᵢ) Exp(δⱼ) (Eade §8.2–8.3, to first
    order), Σ = J Σᵢⱼ Jᵀ with J = [−Ad(Ẑ⁻¹), I] and Σᵢⱼ the pair's joint covariance
    (``marginals``, whose options and refusals these are, computed for every pair in one
    factorisation). Unlike each node's covariance, this does not depend on which node holds
    the gauge. A pair in different connected components is refused (``ValueError``) unless
    both components are set in the world frame (by a held node or a prior)."""
    graph = source.graph if isinstance(source, Smoother) else source
    i, j = graph.index(i_ids), graph.index(j_ids)
    if i.size != j.size:
        raise ValueError(f"pairs need as many i as j ids, not {i.size} and {j.size}")
    labels, framed = graph.components(), graph.components_in_world_frame()
    apart = np.flatnonzero((labels[i] != labels[j]) & ~(framed[labels[i]] & framed[labels[j]]))
    if apart.size:
        ids = graph.node_ids
        k = apart[0]
        raise ValueError(
            f"nodes {ids[i[k]]} and {ids[j[k]]} are in different connected components, not both"
            " set in the world frame by a held node or a prior: nothing measures their relative"
            " pose"
        )
    values = _values(graph, values)
    joint = _group_covariances(
        source, np.stack([i, j], axis=1), values, linear_solver, require_measured
    )
    jacobian = np.concatenate(values[i].between_with_jacobians(values[j])[1:], axis=2)
    return jacobian @ joint @ np.swapaxes(jacobian, 1, 2)


def _values(graph: PoseGraph, values: LieGroup | None) -> LieGroup:
    """``values``, one per node, or the graph's (which must all be set)."""
    if values is None:
        graph.require_values("optimise the graph first (covariances are taken at its values)")
        return graph.values
    if values.batch_shape != (graph.num_nodes,):
        raise ValueError(f"values are one per node ({graph.num_nodes}), not {values.batch_shape}")
    return values


def _group_covariances(
    source: Smoother | PoseGraph,
    groups: np.ndarray,
    values: LieGroup,
    linear_solver: str,
    require_measured: bool,
) -> np.ndarray:
    """The joint covariances (G, k·d, k·d) of G groups of k node indices (G, k) at ``values``,
    as ``marginals`` describes them."""
    smoother = source if isinstance(source, Smoother) else None
    graph = source if smoother is None else smoother.graph
    if smoother is not None and smoother.fixed_lag is not None:
        raise ValueError(
            "covariances of a fixed-lag Smoother's window (its marginal prior with the "
            "measurements since) are not available; pass its graph for the full graph's"
        )
    if smoother is not None:
        edge_weights, prior_weights = smoother.weights()
        if np.any(edge_weights != 1.0) or np.any(prior_weights != 1.0):
            graph = graph.weighted(edge_weights, prior_weights)
    if require_measured:
        direction = undetermined_direction(graph, values, linear_solver)
        if direction is not None:
            raise singular_information(graph, direction=direction)
    # Solves serve any factor, so the last least-squares solve's normal equations do (a back
    # end reading its newest pose's covariance after each step), and H itself where that solve
    # assembled it at these values; for selected inversion, new ones (supernodal, coupled) grow
    # from their pattern.
    system = None if smoother is None else smoother.current_system(linear_solver)
    held = graph.gauge_nodes()
    d = graph.group.dof
    assembled = None
    if not covariance_by_solves(groups.size * d, groups.shape[1] * d):
        system = NormalEquations(graph, held, linear_solver, covariance_of=groups, previous=system)
    elif system is None:
        previous = None if smoother is None else smoother.last_system(linear_solver)
        system = NormalEquations(graph, held, linear_solver, previous=previous)
    else:
        assembled = smoother.current_normal_matrix(values, linear_solver)
    try:
        if assembled is None:
            factorized_information(graph, values, system, least_share=SINGULAR)
        else:
            factorize_information(system, assembled, least_share=SINGULAR)
    except NotPositiveDefinite:
        raise singular_information(graph, values) from None
    return joint_covariances(system, groups)
