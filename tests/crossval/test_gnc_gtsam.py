"""Robust mode against gtsam's own graduated non-convexity (GncLMOptimizer, TLS loss)."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.benchmarks.robust import gtsam_gnc
from posegraph.robust.kernels import default_width
from posegraph.robust.spec import GNC_QUANTILE

gtsam = pytest.importorskip("gtsam")
bridge = pytest.importorskip("posegraph.validation.gtsam_bridge")


@pytest.mark.parametrize("generate", [manhattan_world, sphere], ids=["SE2", "SE3"])
def test_gtsam_threshold_at_the_quantile_is_half_our_width_squared(generate):
    """gtsam thresholds its factor error ½ rᵀΩr; ours thresholds s = rᵀΩr at c²."""
    graph, _ = generate(seed=3)
    factors, initial = bridge.graph_to_gtsam(graph)
    optimizer = gtsam.GncLMOptimizer(factors, initial, gtsam.GncLMParams())
    optimizer.setInlierCostThresholdsAtProbability(GNC_QUANTILE)
    width = default_width(graph.group.dof, GNC_QUANTILE)
    np.testing.assert_allclose(
        np.asarray(optimizer.getInlierCostThresholds()), 0.5 * width**2, rtol=1e-9
    )


@pytest.mark.parametrize("fraction", [0.1, 0.3])
@pytest.mark.parametrize(
    "generate",
    [lambda: manhattan_world(num_poses=300, seed=67), lambda: sphere(rings=6, poses_per_ring=12)],
    ids=["SE2 city", "SE3 sphere"],
)
def test_gnc_rejects_what_gtsam_gnc_rejects_and_reaches_its_solution(generate, fraction):
    """On generated graphs with false loops, gtsam's GNC from the same odometry start, with
    the same loops under a kernel of the same quantile, rejects the same edges, and both end
    at the same poses (to gtsam's LM tolerance)."""
    graph, _ = generate()
    corrupted, false = add_false_loops(graph, fraction, seed=2)
    ours = posegraph.optimize(corrupted.copy(), robust="gnc")
    theirs = gtsam_gnc(corrupted)
    np.testing.assert_array_equal(np.sort(ours.summary.rejected_edges), theirs.rejected_edges)
    np.testing.assert_array_equal(theirs.rejected_edges, np.flatnonzero(false))
    assert theirs.rejected_priors.size == 0
    np.testing.assert_allclose(ours.values.as_matrix(), theirs.values.as_matrix(), atol=1e-4)
