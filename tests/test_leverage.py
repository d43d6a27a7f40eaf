"""Deleted residuals against what leaving each edge out actually does."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere

from posegraph.initialization import odometry_mask
from posegraph.leverage import deleted_residuals
from posegraph.solvers import SolverOptions, optimize
from posegraph.sparse_cholesky import available_backends


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize(
    "graph",
    [manhattan_world(num_poses=150, seed=2)[0], sphere(rings=4, poses_per_ring=10, seed=2)[0]],
    ids=["SE2", "SE3"],
)
def test_deleted_residual_is_the_cost_that_leaving_the_edge_out_saves(graph, backend):
    """At the optimum, d²ₑ (estimated with many probes) equals χ²(all edges) − χ²(without e)
    from re-solving without e, up to the estimate's sampling error and the nonlinearity."""
    options = SolverOptions(linear_solver=backend)
    solution = optimize(graph, options)
    estimated = deleted_residuals(
        graph, solution.values, probes=10000, seed=1, linear_solver=backend
    )
    for edge in np.flatnonzero(~odometry_mask(graph))[:8]:
        keep = np.ones(graph.num_edges, dtype=bool)
        keep[edge] = False
        without = graph.with_edges(keep)
        without.set_values(solution.values)
        saved = solution.summary.final_chi2 - optimize(without, options).summary.final_chi2
        assert estimated[edge] == pytest.approx(saved, rel=0.1, abs=0.1)
