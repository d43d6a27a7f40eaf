"""Conversions between posegraph elements and gtsam 4.3 objects (CONVENTIONS.md, "Peer").

* Tangent orders: ``posegraph.lie.gtsam_order``.
* Similarity3(R, t_g, s) is Eade's [[R, t_g], [0, 1/s]]; ours is N = [[sR, t], [0, 1]], so
  t_g = t / s.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from ..lie import SE2, SE3, SO2, SO3, LieGroup, Sim3
from ..lie.gtsam_order import matrix_to_gtsam, tangent_from_gtsam

GTSAM_TYPE = {
    SO2: gtsam.Rot2,
    SE2: gtsam.Pose2,
    SO3: gtsam.Rot3,
    SE3: gtsam.Pose3,
    Sim3: gtsam.Similarity3,
}


def to_gtsam(element: LieGroup):
    """One element (batch shape ()) as the gtsam object of the same group."""
    if isinstance(element, SO2):
        return gtsam.Rot2(float(element.angle))
    if isinstance(element, SE2):
        x, y = element.translation
        return gtsam.Pose2(float(x), float(y), float(element.angle))
    if isinstance(element, SO3):
        return gtsam.Rot3(element.rotation)
    if isinstance(element, SE3):
        return gtsam.Pose3(gtsam.Rot3(element.rotation), element.translation)
    if isinstance(element, Sim3):
        s = float(element.scale)
        return gtsam.Similarity3(gtsam.Rot3(element.rotation), element.translation / s, s)
    raise TypeError(f"no gtsam counterpart for {type(element).__name__}")


def from_gtsam(value) -> LieGroup:
    """The posegraph element of a gtsam Rot2, Pose2, Rot3, Pose3 or Similarity3."""
    if isinstance(value, gtsam.Rot2):
        return SO2(value.theta())
    if isinstance(value, gtsam.Pose2):
        return SE2(value.theta(), np.array([value.x(), value.y()]))
    if isinstance(value, gtsam.Rot3):
        return SO3(value.matrix())
    if isinstance(value, gtsam.Pose3):
        return SE3(value.rotation().matrix(), value.translation())
    if isinstance(value, gtsam.Similarity3):
        s = value.scale()
        return Sim3(value.rotation().matrix(), value.translation() * s, s)
    raise TypeError(f"no posegraph counterpart for {type(value).__name__}")


# ------------------------------------------------------------------------ factor graphs
_BETWEEN_FACTOR = {
    SE2: gtsam.BetweenFactorPose2,
    SE3: gtsam.BetweenFactorPose3,
    Sim3: gtsam.BetweenFactorSimilarity3,
}
_PRIOR_FACTOR = {
    SE2: gtsam.PriorFactorPose2,
    SE3: gtsam.PriorFactorPose3,
    Sim3: gtsam.PriorFactorSimilarity3,
}
_VALUE_GETTER = {SE2: "atPose2", SE3: "atPose3", Sim3: "atSimilarity3"}

GAUGE_SIGMA = 1e-6
"""Standard deviation of the tight prior that stands in for a held node (datasets README)."""


def _noise_model(group: type[LieGroup], information: np.ndarray):
    return gtsam.noiseModel.Gaussian.Information(matrix_to_gtsam(group, information))


def _edge_noise_model(group: type[LieGroup], information: np.ndarray, huber, edge: int):
    """The Gaussian noise model, made robust by gtsam's Huber kernel where ``huber`` says."""
    gaussian = _noise_model(group, information)
    if huber is None or not huber[0][edge]:
        return gaussian
    kernel = gtsam.noiseModel.mEstimator.Huber.Create(huber[1])
    return gtsam.noiseModel.Robust.Create(kernel, gaussian)


def graph_to_gtsam(graph, values=None, hold_gauge: bool = True, huber=None):
    """(NonlinearFactorGraph, Values) for a PoseGraph; keys are the node ids.

    Held nodes (``graph.gauge_nodes()``) get a prior of σ = ``GAUGE_SIGMA`` at their value,
    which is how gtsam expresses a fixed node; it adds ≈ 0 to the error at that value.
    ``huber``, (edge mask, width): those between edges get gtsam's Huber kernel of that width.
    """
    group = graph.group
    values = graph.values if values is None else values
    ids = graph.node_ids.tolist()
    factors = between_factors(graph, np.arange(graph.num_edges), huber)
    prior = _PRIOR_FACTOR[group]
    for e in range(len(graph.priors)):
        factors.add(
            prior(
                ids[graph.priors.i[e]],
                to_gtsam(graph.priors.measurements[e]),
                _noise_model(group, graph.priors.information[e]),
            )
        )
    if hold_gauge:
        factors.push_back(held_priors(graph, graph.gauge_nodes(), values))
    return factors, values_to_gtsam(graph, np.arange(graph.num_nodes), values)


def between_factors(graph, edges: np.ndarray, huber=None):
    """gtsam's between factors of some of a PoseGraph's edges (indices ``edges``); ``huber`` as
    ``graph_to_gtsam``'s."""
    group, ids, all_edges = graph.group, graph.node_ids.tolist(), graph.edges
    between = _BETWEEN_FACTOR[group]
    factors = gtsam.NonlinearFactorGraph()
    for e in np.asarray(edges).tolist():
        factors.add(
            between(
                ids[all_edges.i[e]],
                ids[all_edges.j[e]],
                to_gtsam(all_edges.measurements[e]),
                _edge_noise_model(group, all_edges.information[e], huber, e),
            )
        )
    return factors


def held_priors(graph, nodes: np.ndarray, values: LieGroup):
    """Priors of σ = ``GAUGE_SIGMA`` that hold the nodes (indices ``nodes``) at ``values``
    (every node's)."""
    group, ids = graph.group, graph.node_ids.tolist()
    sigma = gtsam.noiseModel.Isotropic.Sigma(group.dof, GAUGE_SIGMA)
    factors = gtsam.NonlinearFactorGraph()
    for k in np.asarray(nodes).tolist():
        factors.add(_PRIOR_FACTOR[group](ids[k], to_gtsam(values[k]), sigma))
    return factors


def values_to_gtsam(graph, nodes: np.ndarray, values: LieGroup):
    """gtsam Values of some nodes (indices ``nodes``) of a PoseGraph, from ``values`` (every
    node's), keyed by node id."""
    ids = graph.node_ids.tolist()
    out = gtsam.Values()
    for k in np.asarray(nodes).tolist():
        out.insert(ids[k], to_gtsam(values[k]))
    return out


def values_from_gtsam(graph, gtsam_values, nodes: np.ndarray | None = None) -> LieGroup:
    """The node values of a gtsam Values, in the graph's node order (of the node indices
    ``nodes`` alone, if given)."""
    getter = _VALUE_GETTER[graph.group]
    ids = (graph.node_ids if nodes is None else graph.node_ids[nodes]).tolist()
    return graph.group.stack([from_gtsam(getattr(gtsam_values, getter)(node)) for node in ids])


def gradient_from_gtsam(graph, factors, gtsam_values) -> np.ndarray:
    """(num_nodes, dof) gradient Jᵀ Ω r of gtsam's linearisation, in our tangent order.

    gtsam's Gaussian factor graph holds whitened J and b = −r; its gradient at zero,
    ``gradientAtZero``, is −Jᵀ b = Jᵀ Ω r.
    """
    linear = factors.linearize(gtsam_values)
    gradient = linear.gradientAtZero()
    out = np.zeros((graph.num_nodes, graph.group.dof))
    for k, node in enumerate(graph.node_ids.tolist()):
        out[k] = tangent_from_gtsam(graph.group, gradient.at(node))
    return out


def gnc_tls(
    graph, values: LieGroup, robust_edges: np.ndarray, robust_priors: bool, quantile: float
) -> tuple[LieGroup, np.ndarray, np.ndarray, float]:
    """gtsam's graduated non-convexity with its TLS loss (``GncLMOptimizer``) from ``values``,
    over the between edges in ``robust_edges`` (and the priors, with ``robust_priors``); every
    other factor is a known inlier.

    gtsam's threshold is on its factor error ½ rᵀΩr, so ``setInlierCostThresholdsAtProbability
    (quantile)`` sets ½ χ²_dof(quantile), which is posegraph's c² = χ²_dof(quantile) on rᵀΩr.
    Returns (solution, rejected edges, rejected priors, seconds of gtsam's GNC without the
    conversion); a factor is rejected when its final weight is below ½.
    """
    factors, initial = graph_to_gtsam(graph, values)
    edges, priors = graph.num_edges, len(graph.priors)
    robust = np.zeros(factors.size(), dtype=bool)  # edges, then priors, then gauge priors
    robust[:edges] = robust_edges
    robust[edges : edges + priors] = robust_priors
    params = gtsam.GncLMParams(gtsam.LevenbergMarquardtParams())
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(np.flatnonzero(~robust).tolist())
    start = time.perf_counter()
    optimizer = gtsam.GncLMOptimizer(factors, initial, params)
    optimizer.setInlierCostThresholdsAtProbability(quantile)
    solution = optimizer.optimize()
    seconds = time.perf_counter() - start
    rejected = np.flatnonzero(robust & (np.asarray(optimizer.getWeights()) < 0.5))
    return (
        values_from_gtsam(graph, solution),
        rejected[rejected < edges],
        rejected[rejected >= edges] - edges,
        seconds,
    )
