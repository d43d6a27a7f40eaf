"""Marginal covariances of nodes and of relative poses: their weights after a robust solve, the
reuse of the last solve's factorisation, their refusals."""

from __future__ import annotations

import copy
import importlib

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.graph import PoseGraph
from posegraph.lie import SE2, SE3, SO3, Sim3
from posegraph.lie.uncertainty import compose_covariance, inverse_covariance
from posegraph.problem import cholesky as sparse_cholesky
from posegraph.problem.backends import available_backends
from posegraph.problem.cholesky import COUPLED_COLUMNS, SOLVED_COLUMNS, NotPositiveDefinite
from posegraph.problem.factors import linearize_between, linearize_priors
from posegraph.problem.linear import NormalEquations
from tests.smoother.helpers import count_normal_equations

from ..conftest import cull, random_graph, union


def test_marginals_after_gnc_leave_the_rejected_loops_out():
    """A back end that rejects false loop closures must not have them shrink its covariances:
    after GNC they are those of the graph without the false loops. Before, every rejected loop
    counted with its full information."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    corrupted, false = add_false_loops(graph, 0.1, seed=1)
    robust = posegraph.Smoother(corrupted)
    result = robust.optimize(robust="gnc")
    np.testing.assert_array_equal(result.summary.rejected_edges, np.flatnonzero(false))
    posegraph.optimize(graph)
    nodes = graph.node_ids[[40, 90, 149]]
    np.testing.assert_allclose(
        posegraph.marginals(robust, nodes), posegraph.marginals(graph, nodes), rtol=1e-5
    )
    # An edge added since the solution counts in full until the next solve weighs it.
    corrupted.add_edge(0, 149, graph.values[0].between(graph.values[149]), np.eye(3) * 1e4)
    graph.add_edge(0, 149, graph.values[0].between(graph.values[149]), np.eye(3) * 1e4)
    np.testing.assert_allclose(
        posegraph.marginals(robust, nodes, values=graph.values),
        posegraph.marginals(graph, nodes, values=graph.values),
        rtol=1e-9,
    )


def test_marginals_after_culling_still_leave_the_rejected_loops_out():
    """A keyframe culled after GNC: the weights stay with the edges that remain, so the
    covariances are still those of the inliers, at the same values; with every loop counted
    in full they would be smaller."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    corrupted, false = add_false_loops(graph, 0.1, seed=1)
    smoother = posegraph.Smoother(corrupted)
    smoother.optimize(robust="gnc")
    cull(smoother, 75)
    nodes = corrupted.node_ids[[40, 74, 148]]
    ours = posegraph.marginals(smoother, nodes)
    inliers = smoother.without_rejected()
    assert inliers.num_edges == corrupted.num_edges - np.count_nonzero(false) > 0
    np.testing.assert_allclose(ours, posegraph.marginals(inliers, nodes), rtol=1e-9)
    counted_in_full = corrupted.copy()
    in_full = np.trace(posegraph.marginals(counted_in_full, nodes), axis1=1, axis2=2)
    assert np.all(in_full < 0.95 * np.trace(ours, axis1=1, axis2=2))


def test_the_newest_poses_covariance_fills_the_last_solves_normal_equations(monkeypatch):
    """A back end reads its newest pose's covariance after each step: the normal equations of
    the step's solve (pattern and CHOLMOD's analysis) serve it, refilled at the optimum; after
    a structural change they are built anew. Either way the covariance is that of a graph
    never optimised here (a copy, which has no cached system)."""
    graph, _ = manhattan_world(num_poses=120, seed=88)
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    newest = graph.node_ids[-1:]
    built = count_normal_equations(monkeypatch)
    covariance = posegraph.marginals(smoother, newest)
    assert built == []
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), newest), rtol=1e-10)
    graph.add_edge(int(graph.node_ids[0]), int(newest[0]), SE2.identity(), np.eye(3))
    built.clear()
    covariance = posegraph.marginals(smoother, newest)
    assert built == [1]
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), newest), rtol=1e-10)


def test_the_covariance_at_the_solution_factorises_h_of_the_solves_linearisation(monkeypatch):
    """At the solution of a least-squares solve, the covariance factorises H of the solve's
    linearisation there, without linearising again; at other values, and after a robust
    solve (whose H holds IRLS weights), it linearises. The covariance is the same either way
    (a copy, which has no cached solve, computes it afresh)."""
    graph, _ = manhattan_world(num_poses=120, seed=88)
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    nodes = graph.node_ids[[-1, 40]]
    linearised = []
    # The package's attribute posegraph.marginals is the function, so the module by its name.
    marginals_module = importlib.import_module("posegraph.analysis.marginals")
    fresh = marginals_module.factorized_information

    def counted(*args, **kwargs):
        linearised.append(1)
        return fresh(*args, **kwargs)

    monkeypatch.setattr(marginals_module, "factorized_information", counted)
    covariance = posegraph.marginals(smoother, nodes)
    assert linearised == []
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), nodes), rtol=1e-10)
    moved = graph.values.retract(np.full((graph.num_nodes, 3), 0.01))
    linearised.clear()
    np.testing.assert_allclose(
        posegraph.marginals(smoother, nodes, values=moved),
        posegraph.marginals(graph.copy(), nodes, values=moved),
        rtol=1e-10,
    )
    assert linearised == [1, 1]
    smoother.optimize(robust="huber")
    linearised.clear()
    covariance = posegraph.marginals(smoother, nodes)
    assert linearised == [1]
    copied = copy.deepcopy(smoother)  # the same weights, no cached solve
    np.testing.assert_allclose(covariance, posegraph.marginals(copied, nodes), rtol=1e-10)


@pytest.mark.skipif("cholmod" not in available_backends(), reason="no cvxopt")
def test_covariances_from_a_simplicial_ldlt_factor(monkeypatch):
    """With CHOLMOD set to simplicial factors (P A Pᵀ = L D Lᵀ), the solve's normal equations
    still give the covariance: D enters the solves."""
    from cvxopt import cholmod

    graph = random_graph(SE3, 30, 12, seed=89)
    monkeypatch.setitem(cholmod.options, "supernodal", 0)
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    nodes = graph.node_ids[[4, 20]]
    reused = posegraph.marginals(smoother, nodes)
    monkeypatch.delitem(cholmod.options, "supernodal")
    np.testing.assert_allclose(reused, posegraph.marginals(graph.copy(), nodes), rtol=1e-10)


@pytest.mark.parametrize("backend", available_backends())
def test_covariances_are_symmetric_to_the_last_bit(backend):
    """Solves leave rounding asymmetry (SuperLU's did, by up to 1e-7 relative on graphs of
    information singular to rounding); a covariance handed out is symmetric exactly."""
    graph = random_graph(SE3, 30, 12, seed=86, noise=0.05)
    posegraph.optimize(graph)
    nodes = graph.node_ids[[2, 9, 17, 25]]
    blocks = posegraph.marginals(graph, nodes, linear_solver=backend)
    joint = posegraph.marginals(graph, nodes, joint=True, linear_solver=backend)
    np.testing.assert_array_equal(blocks, np.swapaxes(blocks, 1, 2))
    np.testing.assert_array_equal(joint, joint.T)


@pytest.mark.parametrize("backend", available_backends())
def test_covariances_of_information_singular_to_working_precision_are_refused(backend):
    """A prior whose information has eigenvalues 1, 2 and 1e-14 (in turned axes): H factorises,
    its least pivot at rounding's scale, and its inverse would keep two digits. It is refused
    as a singular H is, naming the node. At 1e-10, the covariance is Ω⁻¹."""
    turn = SO3.exp(np.array([0.3, -0.5, 0.7])).rotation
    for least, refused in ((1e-14, True), (1e-10, False)):
        graph = PoseGraph(SE2)
        graph.add_node(7, SE2.identity())
        information = turn @ np.diag([1.0, 2.0, least]) @ turn.T
        graph.add_prior(7, SE2.identity(), 0.5 * (information + information.T))
        if refused:
            with pytest.raises(NotPositiveDefinite, match=r"\(node 7: 1 of its 3 directions\)"):
                posegraph.marginals(graph, [7], linear_solver=backend)
        else:
            covariance = posegraph.marginals(graph, [7], linear_solver=backend)[0]
            expected = np.linalg.inv(graph.priors.information[0])
            np.testing.assert_allclose(covariance, expected, rtol=1e-5, atol=1e-5 * 1e10)


@pytest.mark.parametrize(
    ("solved_columns", "coupled_columns"),
    [(SOLVED_COLUMNS, COUPLED_COLUMNS), (0, COUPLED_COLUMNS), (0, 0)],
    ids=["as set", "selected inversion", "joint by solves"],
)
def test_marginals_are_blocks_of_the_inverse_information(
    monkeypatch, solved_columns, coupled_columns
):
    """Against a dense inverse of H on a small graph (the library never forms one), by solves,
    by selected inversion, and with joint covariances too large to couple into the pattern."""
    monkeypatch.setattr(sparse_cholesky, "SOLVED_COLUMNS", solved_columns)
    monkeypatch.setattr(sparse_cholesky, "COUPLED_COLUMNS", coupled_columns)
    graph = random_graph(SE3, 12, 8, seed=85, noise=0.05, priors=0)
    posegraph.optimize(graph)
    held = graph.gauge_nodes()
    system = NormalEquations(graph, held, "scipy")
    data = system.normal_matrix(
        linearize_between(graph.values, graph.edges),
        graph.edges.information,
        linearize_priors(graph.values, graph.priors),
        graph.priors.information,
    )
    inverse = np.linalg.inv(system.matrix(data).toarray())
    nodes = graph.node_ids[[3, 7]]
    cov = posegraph.marginals(graph, nodes)
    for k, node in enumerate([3, 7]):
        block = slice(system.block_of[node] * 6, system.block_of[node] * 6 + 6)
        np.testing.assert_allclose(cov[k], inverse[block, block], rtol=1e-9, atol=1e-12)
    joint = posegraph.marginals(graph, nodes, joint=True)
    rows = np.r_[
        system.block_of[3] * 6 : system.block_of[3] * 6 + 6,
        system.block_of[7] * 6 : system.block_of[7] * 6 + 6,
    ]
    np.testing.assert_allclose(joint, inverse[np.ix_(rows, rows)], rtol=1e-9, atol=1e-12)
    assert np.all(posegraph.marginals(graph, graph.node_ids[held]) == 0)  # the gauge is exact
    assert posegraph.marginals(graph, []).shape == (0, 6, 6)
    assert posegraph.marginals(graph, [], joint=True).shape == (0, 0)
    every_node_held = graph.copy()
    every_node_held.fix(graph.node_ids)
    assert np.all(posegraph.marginals(every_node_held, graph.node_ids[:2]) == 0)
    for backend in ("scipy",):
        np.testing.assert_allclose(
            posegraph.marginals(graph, nodes, linear_solver=backend), cov, rtol=1e-8
        )
    np.testing.assert_allclose(posegraph.marginals(graph, nodes, values=graph.values), cov)
    with pytest.raises(ValueError, match=r"values are one per node \(12\), not \(2,\)"):
        posegraph.marginals(graph, nodes, values=graph.values[:2])
    graph.add_node(99)  # no value until the graph is optimised again
    graph.add_edge(int(graph.node_ids[0]), 99, SE3.identity(), np.eye(6))
    with pytest.raises(ValueError, match=r"nodes \[99\] have no values; optimise the graph first"):
        posegraph.marginals(graph, [99])


@pytest.mark.parametrize("group", [SE2, SE3, Sim3])
def test_relative_covariances_along_a_tree_compose_its_measurements_covariances(group):
    """Where one path of edges joins two nodes (a chain, at its optimum: every residual zero),
    the covariance of their relative pose is that of the path's composed measurements, by
    Eade §8.2 applied edge after edge (and §8.3 for the reverse pair), whichever node holds
    the gauge."""
    rng = np.random.default_rng(86)
    d = group.dof
    measurements = group.exp(0.4 * rng.normal(size=(5, d)))
    a = rng.normal(size=(5, d, d))
    information = a @ np.swapaxes(a, 1, 2) + d * np.eye(d)
    graph = PoseGraph(group)
    graph.add_nodes(range(6))
    graph.add_edges(range(5), range(1, 6), measurements, information)
    posegraph.optimize(graph)
    path, covariance = measurements[1], np.linalg.inv(information[1])
    for k in (2, 3):
        step = np.linalg.inv(information[k])
        covariance = compose_covariance(path, covariance, measurements[k], step)
        path = path @ measurements[k]
    for held in (0, 5):
        graph.fix(graph.node_ids, False)
        graph.fix([held])
        relative = posegraph.relative_covariances(graph, [1, 4, held, 2], [4, 1, 3, 2])
        np.testing.assert_allclose(relative[0], covariance, rtol=1e-8, atol=1e-12)
        reverse = inverse_covariance(path, covariance)
        np.testing.assert_allclose(relative[1], reverse, rtol=1e-8, atol=1e-12)
        # From a held node, the marginal; a node against itself, none.
        np.testing.assert_allclose(relative[2], posegraph.marginals(graph, [3])[0], rtol=1e-8)
        np.testing.assert_allclose(relative[3], 0.0, atol=1e-12 * np.abs(covariance).max())


def test_relative_covariances_do_not_depend_on_the_gauge_where_marginals_do():
    """Held at another node, a Manhattan world's poses have other covariances, and their
    relative poses the same ones (1e-9), by solves and by selected inversion."""
    graph, _ = manhattan_world(200, seed=87)
    posegraph.optimize(graph)
    regauged = graph.copy()
    regauged.fix([0], False)
    regauged.fix([120])
    rng = np.random.default_rng(87)
    for count in (3, 40):  # 18 columns by solves; 240 by selected inversion
        i, j = rng.choice(graph.node_ids, (2, count))
        ours, theirs = (posegraph.relative_covariances(g, i, j) for g in (graph, regauged))
        np.testing.assert_allclose(theirs, ours, rtol=1e-9, atol=1e-12 * np.abs(ours).max())
        marginal = posegraph.marginals(graph, j)
        assert not np.allclose(posegraph.marginals(regauged, j), marginal, rtol=1e-3)


def test_relative_covariances_need_a_measured_relative_pose():
    """Two maps apart: their nodes' relative pose is refused, unless a hold or a prior sets
    each map in the world frame; pairs of unequal counts are refused."""
    first, second = (random_graph(SE2, 6, 2, seed=s) for s in (88, 89))
    graph = union(first, second, id_offset=1000)
    posegraph.optimize(graph)
    a, b = int(first.node_ids[2]), int(second.node_ids[3]) + 1000
    assert posegraph.relative_covariances(graph, [a], [int(first.node_ids[4])]).shape == (1, 3, 3)
    message = rf"nodes {a} and {b} are in different connected components, not both set"
    with pytest.raises(ValueError, match=message):
        posegraph.relative_covariances(graph, [a], [b])
    graph.fix([int(first.node_ids[0])])
    with pytest.raises(ValueError, match=message):
        posegraph.relative_covariances(graph, [a], [b])
    graph.add_prior(b, graph.values_of([b])[0], np.eye(3))
    posegraph.optimize(graph)
    apart = posegraph.relative_covariances(graph, [a], [b])[0]
    # One map held by a node, the other by a prior: the poses are independent (Eade §8.2).
    x_a, x_b = graph.values_of([a]), graph.values_of([b])
    marginal = posegraph.marginals(graph, [a, b])
    expected = compose_covariance(
        x_a.inverse()[0], inverse_covariance(x_a[0], marginal[0]), x_b[0], marginal[1]
    )
    np.testing.assert_allclose(apart, expected, rtol=1e-9)
    with pytest.raises(ValueError, match="as many i as j ids, not 1 and 2"):
        posegraph.relative_covariances(graph, [a], [a, b])
    assert posegraph.relative_covariances(graph, [], []).shape == (0, 3, 3)
