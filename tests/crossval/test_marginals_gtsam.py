"""Marginal covariances against gtsam.Marginals, after the tangent permutation."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.api import robust_mask

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
        expected = bridge.matrix_from_gtsam(graph.group, theirs.marginalCovariance(node))
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())
    together = nodes[: count // 2 if count > 10 else 2].tolist()
    joint = posegraph.marginals(graph, together, joint=True)
    permutation = np.kron(np.eye(len(together)), bridge.tangent_permutation(graph.group))
    expected = permutation.T @ theirs.jointMarginalCovariance(together).fullMatrix() @ permutation
    np.testing.assert_allclose(joint, expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


def test_marginals_after_a_robust_solve_weigh_edges_as_gtsams_robust_noise_models():
    """After a Huber solve with 10% false loops, each loop's information counts with its IRLS
    weight at the solution, as gtsam's Robust noise model weighs it when linearised; before,
    every false loop counted in full, and the covariances came out too small."""
    graph, _ = manhattan_world(num_poses=150, seed=91)
    corrupted, _ = add_false_loops(graph, 0.1, seed=0)
    width = 2.5
    posegraph.optimize(corrupted, robust=f"huber:{width}")
    nodes = np.random.default_rng(92).choice(corrupted.node_ids[1:], 6, replace=False)
    ours = posegraph.marginals(corrupted, nodes)
    factors, values = bridge.graph_to_gtsam(
        corrupted, huber=(robust_mask(corrupted, "loops"), width)
    )
    theirs = gtsam.Marginals(factors, values)
    for k, node in enumerate(nodes.tolist()):
        expected = bridge.matrix_from_gtsam(corrupted.group, theirs.marginalCovariance(node))
        np.testing.assert_allclose(ours[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())
