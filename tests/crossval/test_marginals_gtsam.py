"""Marginal covariances against gtsam.Marginals, after the tangent permutation."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.lie import gtsam_order
from posegraph.robust.spec import robust_mask

gtsam = pytest.importorskip("gtsam")
bridge = pytest.importorskip("posegraph.validation.gtsam_bridge")


@pytest.mark.parametrize("name", ["sphere2500.g2o", "intel.g2o"])
@pytest.mark.parametrize("count", [10, 40])
def test_marginals_equal_gtsam(shared_dataset, name, count):
    """Random nodes, 1e-6 relative; gtsam holds the gauge node with a σ = 1e-6 prior. With 10
    nodes, posegraph solves with their unit columns; with 40 (and the joint covariance of 20),
    more columns than ``SOLVED_COLUMNS``, it inverts the factor selectively."""
    graph = posegraph.read_graph(str(shared_dataset(name))).graph
    posegraph.optimize(graph)
    nodes = np.random.default_rng(90).choice(graph.node_ids[1:], count, replace=False)
    ours = posegraph.marginals(graph, nodes)
    factors, values = bridge.graph_to_gtsam(graph)
    theirs = gtsam.Marginals(factors, values)
    for k, node in enumerate(nodes.tolist()):
        expected = gtsam_order.matrix_from_gtsam(graph.group, theirs.marginalCovariance(node))
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())
    together = nodes[: count // 2 if count > 10 else 2].tolist()
    joint = posegraph.marginals(graph, together, joint=True)
    permutation = np.kron(np.eye(len(together)), gtsam_order.tangent_permutation(graph.group))
    expected = permutation.T @ theirs.jointMarginalCovariance(together).fullMatrix() @ permutation
    np.testing.assert_allclose(joint, expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


def test_marginals_after_a_robust_solve_weigh_edges_as_gtsams_robust_noise_models():
    """After a Huber solve with 10% false loops, each loop's information counts with its IRLS
    weight at the solution, as gtsam's Robust noise model weighs it when linearised; before,
    every false loop counted in full, and the covariances came out too small."""
    graph, _ = manhattan_world(num_poses=150, seed=91)
    corrupted, _ = add_false_loops(graph, 0.1, seed=0)
    width = 2.5
    smoother = posegraph.Smoother(corrupted)
    smoother.optimize(robust=f"huber:{width}")
    nodes = np.random.default_rng(92).choice(corrupted.node_ids[1:], 6, replace=False)
    ours = posegraph.marginals(smoother, nodes)
    factors, values = bridge.graph_to_gtsam(
        corrupted, huber=(robust_mask(corrupted, "loops"), width)
    )
    theirs = gtsam.Marginals(factors, values)
    for k, node in enumerate(nodes.tolist()):
        expected = gtsam_order.matrix_from_gtsam(corrupted.group, theirs.marginalCovariance(node))
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


def _derivative_of_between(pose_i, pose_j) -> np.ndarray:
    """d × 2d: the derivative of Log(Ẑ⁻¹ · (Xᵢ Exp(ξᵢ))⁻¹ (Xⱼ Exp(ξⱼ))), Ẑ = Xᵢ⁻¹Xⱼ, in
    gtsam's tangent, by central differences of gtsam's own operations."""
    pose_type = type(pose_i)
    relative = pose_i.between(pose_j)
    dof = pose_type.Logmap(relative).size
    step = 1e-6
    columns = []
    for k in range(2 * dof):
        ends = []
        for sign in (1.0, -1.0):
            xi = np.zeros(2 * dof)
            xi[k] = sign * step
            moved_i = pose_i.compose(pose_type.Expmap(xi[:dof]))
            moved_j = pose_j.compose(pose_type.Expmap(xi[dof:]))
            ends.append(pose_type.Logmap(relative.between(moved_i.between(moved_j))))
        columns.append((ends[0] - ends[1]) / (2 * step))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("name", ["sphere2500.g2o", "intel.g2o"])
def test_relative_covariances_equal_gtsams_joint_marginals_through_its_between(
    shared_dataset, name
):
    """gtsam's joint marginal of each pair, mapped through the derivative of gtsam's own
    between (central differences in its tangent), equals ours after the tangent permutation,
    for 12 random pairs at once (1e-6 relative)."""
    graph = posegraph.read_graph(str(shared_dataset(name))).graph
    posegraph.optimize(graph)
    i, j = np.random.default_rng(93).choice(graph.node_ids[1:], (2, 12), replace=False)
    ours = posegraph.relative_covariances(graph, i, j)
    factors, values = bridge.graph_to_gtsam(graph)
    marginals = gtsam.Marginals(factors, values)
    for k, (a, b) in enumerate(zip(i.tolist(), j.tolist(), strict=True)):
        joint = marginals.jointMarginalCovariance([a, b])
        covariance = np.block([[joint.at(a, a), joint.at(a, b)], [joint.at(b, a), joint.at(b, b)]])
        poses = (bridge.to_gtsam(graph.values_of([node])[0]) for node in (a, b))
        derivative = _derivative_of_between(*poses)
        expected = gtsam_order.matrix_from_gtsam(
            graph.group, derivative @ covariance @ derivative.T
        )
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())
