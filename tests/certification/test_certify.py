"""Certification against independent checks: the semidefinite relaxation solved by a conic
solver (cvxpy with Clarabel) on small graphs, SE-Sync's cost written out edge by edge, and
torus3D's bad local minimum, from which the staircase reaches the certified optimum."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets.generators import grid, manhattan_world, visual_odometry
from posegraph_datasets.paths import benchmark_graph

import posegraph
from posegraph.certification.data import precisions, sesync_data
from posegraph.lie import SE2, SE3


def sesync_cost(graph, values) -> float:
    """Σ κ ‖Rⱼ − Rᵢ R̃‖²_F + τ ‖tⱼ − tᵢ − Rᵢ t̃‖², edge by edge (SE-Sync's Problem 1)."""
    d = 2 if graph.group is SE2 else 3
    kappa, tau = precisions(graph.group, graph.edges.information)
    x, z = values.as_matrix(), graph.edges.measurements.as_matrix()
    i, j = graph.edges.i, graph.edges.j
    r_i, r_j, t_i, t_j = x[i, :d, :d], x[j, :d, :d], x[i, :d, d], x[j, :d, d]
    rotation = np.sum((r_j - r_i @ z[:, :d, :d]) ** 2, axis=(1, 2))
    translation = np.sum((t_j - t_i - np.einsum("mab,mb->ma", r_i, z[:, :d, d])) ** 2, axis=1)
    return float(kappa @ rotation + tau @ translation)


def semidefinite_relaxation(graph) -> tuple[float, np.ndarray]:
    """min tr(Q Z) over Z ⪰ 0 with identity diagonal blocks (SE-Sync's Problem 7), by cvxpy."""
    cvxpy = pytest.importorskip("cvxpy")
    data = sesync_data(graph)
    size, d = data.d * data.n, data.d
    q = data.product(np.eye(size))
    q = 0.5 * (q + q.T)
    z = cvxpy.Variable((size, size), PSD=True)
    constraints = [z[k * d : (k + 1) * d, k * d : (k + 1) * d] == np.eye(d) for k in range(data.n)]
    problem = cvxpy.Problem(cvxpy.Minimize(cvxpy.trace(q @ z)), constraints)
    problem.solve(solver=cvxpy.CLARABEL)
    return float(problem.value), np.linalg.eigvalsh(z.value)


@pytest.mark.parametrize(
    "graph",
    [
        visual_odometry(SE2, poses=25, seed=1)[0],
        manhattan_world(num_poses=30, grid_size=4, seed=2)[0],
        grid(size=2, seed=3)[0],
    ],
    ids=["SE2 odometry", "SE2 manhattan", "SE3 grid"],
)
def test_the_certified_objective_is_the_relaxations_optimum(graph):
    graph.priors = graph.priors.subset(np.zeros(len(graph.priors), dtype=bool))
    rng = np.random.default_rng(0)
    start = graph.values.retract(rng.normal(scale=1.0, size=(graph.num_nodes, graph.group.dof)))
    certificate = posegraph.certify(graph, start)  # from scrambled rotations
    optimum, eigenvalues = semidefinite_relaxation(graph)
    assert certificate.certified
    assert certificate.objective == pytest.approx(optimum, rel=1e-6)
    d = 2 if graph.group is SE2 else 3
    assert eigenvalues[-d - 1] < 1e-6 * eigenvalues[-1]  # the relaxation's solution has rank d
    assert sesync_cost(graph, certificate.values) == pytest.approx(certificate.objective, rel=1e-9)


def test_a_check_that_fails_names_a_lower_bound_and_priors_are_refused():
    graph, _ = grid(size=2, seed=4)
    certificate = posegraph.certify(graph, max_rank=3, values=_reflected(graph))
    for step in certificate.steps:
        assert step["smallest_eigenvalue"] < certificate.tolerance or step is certificate.steps[-1]
    assert certificate.lower_bound <= certificate.objective + 1e-9
    graph.add_prior(0, SE3.identity(), np.eye(6))
    with pytest.raises(ValueError, match="no priors"):
        posegraph.certify(graph)


def _reflected(graph):
    """Every other pose turned half a turn about x: a start far from the optimum."""
    turn = SE3.exp(np.array([0, 0, 0, np.pi * 0.9, 0, 0]))
    values = graph.values
    flipped = values[1::2] @ turn
    return values.set_at(np.arange(1, graph.num_nodes, 2), flipped)


def test_torus3d_from_the_files_values_is_not_certified_until_the_staircase_climbs():
    path = benchmark_graph("torus3D.g2o")
    if path is None:
        pytest.skip("torus3D.g2o is not in ../shared/datasets or POSEGRAPH_DATASETS")
    graph = posegraph.read_graph(path).graph
    options = posegraph.SolverOptions(max_iterations=15)  # 100 creep on to 29950.47
    error = posegraph.optimize(graph, init="file", options=options).summary.final_error
    assert 29950 < error < 30500  # Levenberg-Marquardt's basin from the file; the optimum: 12117.6
    certificate = posegraph.certify(graph)
    first, last = certificate.steps[0], certificate.steps[-1]
    assert first["rank"] == 3 and first["smallest_eigenvalue"] < -certificate.tolerance
    assert certificate.rank > 3 and certificate.certified
    assert last["rank"] == 3
    assert f"{certificate.objective:.4g}" == "2.423e+04"  # SE-Sync's published optimum


def test_a_block_without_information_in_some_direction_is_refused_by_name():
    graph, _ = grid(size=2, seed=8)
    information = graph.edges.information.copy()
    information[3, 0, :] = information[3, :, 0] = 0.0  # x of edge 3 is not measured
    graph.edges = dataclasses.replace(graph.edges, information=information)
    i, j = graph.node_ids[graph.edges.i[3]], graph.node_ids[graph.edges.j[3]]
    with pytest.raises(ValueError, match=f"edge {i} → {j}: its translation information is not"):
        posegraph.certify(graph)
