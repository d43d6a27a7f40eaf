"""Factor Jacobians and optima against an independent casadi formulation (ipopt)."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph import PoseGraph
from posegraph.io import read_graph
from posegraph.lie import SE2
from posegraph.problem.factors import linearize_between
from posegraph.solvers import solve

from ..conftest import POSE_GROUPS, random_graph

ca = pytest.importorskip("casadi")
casadi_model = pytest.importorskip("posegraph.validation.casadi_model")


@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_between_jacobians_equal_casadi(group):
    graph = random_graph(group, 8, 6, seed=11, noise=0.4)
    lin = linearize_between(graph.values, graph.edges)
    nodes = graph.values.as_matrix()
    measurements = graph.edges.measurements.as_matrix()
    for k in range(graph.num_edges):
        jac_i, jac_j = casadi_model.between_jacobians(
            group, nodes[graph.edges.i[k]], nodes[graph.edges.j[k]], measurements[k]
        )
        np.testing.assert_allclose(lin.jac_i[k], jac_i, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(lin.jac_j[k], jac_j, rtol=1e-9, atol=1e-9)


def _ipopt_optimum(graph: PoseGraph) -> float:
    held = graph.gauge_nodes()
    delta, cost, _ = casadi_model.graph_cost(graph, held)
    solver = ca.nlpsol(
        "pose_graph",
        "ipopt",
        {"x": delta, "f": cost},
        {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-12},
    )
    solution = solver(x0=np.zeros(delta.shape[0]))
    assert solver.stats()["return_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    return float(solution["f"])


def _se2_loop(num_nodes: int = 20, seed: int = 12) -> PoseGraph:
    """A noisy square loop of SE2 poses, closed back to the start."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(0, 2 * np.pi, num_nodes, endpoint=False)
    truth = SE2(angles + np.pi / 2, 5.0 * np.stack([np.cos(angles), np.sin(angles)], axis=1))
    i = np.arange(num_nodes)
    j = (i + 1) % num_nodes
    measured = truth[i].between(truth[j]).retract(0.05 * rng.normal(size=(num_nodes, 3)))
    graph = PoseGraph(SE2)
    graph.add_nodes(i, truth.retract(0.2 * rng.normal(size=(num_nodes, 3))))
    graph.add_edges(i, j, measured, np.diag([100.0, 100.0, 400.0]))
    return graph


def test_se2_loop_optimum_equals_ipopt():
    graph = _se2_loop()
    ours = solve(graph).summary.final_error
    assert abs(ours - _ipopt_optimum(graph)) <= 1e-6 * ours


def test_tiny_grid_optimum_equals_ipopt(shared_dataset):
    graph = read_graph(shared_dataset("tinyGrid3D.g2o")).graph
    ours = solve(graph).summary.final_error
    assert abs(ours - _ipopt_optimum(graph)) <= 1e-6 * ours
