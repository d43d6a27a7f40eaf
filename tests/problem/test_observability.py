"""Directions that no measurement reaches: found per node and over the graph, damped by the solver,
refused by covariances."""

from __future__ import annotations

import numpy as np
import pytest

import posegraph
from posegraph.graph import PoseGraph
from posegraph.init.chordal import chordal_values
from posegraph.lie import SE2, SE3, Sim3
from posegraph.problem import observability
from posegraph.problem.cholesky import NotPositiveDefinite
from posegraph.problem.factors import (
    between_jacobians,
    between_residuals,
    information_root,
    relative_poses,
)
from posegraph.problem.observability import (
    tied_by_full_rank,
    undetermined_direction,
    unmeasured_directions,
    unmeasured_share,
)
from posegraph.solvers import SolverOptions
from tests.robust.helpers import factorised_direction

from ..conftest import (
    city_with_fixes,
    gnss_track,
    maps_joined_by_positions,
    random_graph,
)


def _with_partial_leaf(group, measured: str) -> tuple[PoseGraph, np.ndarray]:
    """A loopy graph with a leaf node 9999 joined by one edge that measures only its position
    (or only its rotation), and the mask of the leaf's tangent directions nothing measures."""
    graph = random_graph(group, 15, 8, seed=68, noise=0.02)
    d, dof = group.point_dim, group.dof
    position = np.arange(dof) < d
    kept = (
        position
        if measured == "position"
        else (np.arange(dof) >= d) & (np.arange(dof) < dof - (group is Sim3))
    )
    information = np.diag(np.where(kept, 100.0, 0.0))
    leaf = group.exp(np.random.default_rng(69).normal(size=(1, dof)))
    graph.add_nodes([9999], leaf)
    measurement = graph.values[3].between(leaf).retract(np.full((1, dof), 0.01))
    graph.add_edges([graph.node_ids[3]], [9999], measurement, information[None])
    return graph, ~kept


@pytest.mark.parametrize("measured", ["position", "rotation"])
@pytest.mark.parametrize("group", [SE2, SE3, Sim3], ids=lambda g: g.__name__)
def test_a_node_with_directions_nothing_measures_is_optimised_from_every_start(group, measured):
    """A leaf seen only by a position-only (or rotation-only) edge: chordal relaxation's
    rotation (or translation) system had a zero row there, which no relative ridge ε diag(H)
    could fix, and ``optimize`` with defaults failed (NotPositiveDefinite; the CLI's exit 3).
    The leaf can always meet its one edge, so the optimum is that of the graph without it:
    every initialiser and GNC now reach it, and chordal relaxation leaves the leaf's
    unmeasured directions at their values. From the graph's own values, Levenberg-Marquardt
    crawled on the SE3 leaf seen by position only (100 iterations, not converged): Marquardt's
    damping turned it by radians a step (``solvers.optimize``'s docstring)."""
    graph, unmeasured = _with_partial_leaf(group, measured)
    expected = np.zeros(graph.num_nodes, dtype=int)
    expected[-1] = np.count_nonzero(unmeasured)
    np.testing.assert_array_equal(unmeasured_directions(graph), expected)
    without_leaf = graph.subgraph(graph.node_ids != 9999)
    best = posegraph.optimize(without_leaf, init="file").summary
    assert best.converged
    for init in ("file", "auto", "odometry", "spanning-tree", "chordal"):
        summary = posegraph.optimize(graph.copy(), init=init).summary
        assert summary.converged, init
        assert summary.final_error == pytest.approx(best.final_error, rel=1e-6), init
    summary = posegraph.optimize(graph.copy(), robust="gnc").summary
    assert summary.final_error == pytest.approx(best.final_error, rel=1e-6)
    for init in ("file", "auto"):  # the dogleg holds those directions back as LM damps them
        summary = posegraph.optimize(graph.copy(), init, SolverOptions(method="dogleg")).summary
        assert summary.converged, init
        assert summary.final_error == pytest.approx(best.final_error, rel=1e-6), init
    leaf, started = chordal_values(graph)[-1].as_matrix(), graph.values[-1].as_matrix()
    d = group.point_dim
    if measured == "position":  # the rotation (and Sim3's scale: s R) are not measured
        np.testing.assert_allclose(leaf[:d, :d], started[:d, :d], atol=1e-12)
    else:  # the translation (and Sim3's scale) are not measured
        np.testing.assert_allclose(leaf[:d, d], started[:d, d], atol=1e-12)
        if group is Sim3:
            np.testing.assert_allclose(np.linalg.det(leaf[:d, :d]), np.linalg.det(started[:d, :d]))


def test_unmeasured_share_is_the_diagonal_of_the_projector_onto_unmeasured_directions():
    """On an axis (the SE3 leaf's rotation, seen by position only) the share is 1, elsewhere 0.
    Node 1 of a pair joined by one position-only edge 1 → 0 can turn about node 0's position,
    a direction that mixes its rotation and translation: its share is the diagonal of
    I − M⁺M, with M its block Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) (``observability``'s docstring), here
    formed with a pseudo-inverse."""
    graph, unmeasured = _with_partial_leaf(SE3, "position")
    expected = np.zeros((graph.num_nodes, SE3.dof))
    expected[-1] = unmeasured
    np.testing.assert_allclose(unmeasured_share(graph), expected, atol=1e-12)

    pair = PoseGraph(SE3)
    pair.add_nodes([0, 1], SE3.exp(np.random.default_rng(71).normal(size=(2, 6))))
    measurement = SE3.exp(np.array([[0.4, -1.0, 2.0, 0.3, 0.2, -0.5]]))
    information = np.diag([4.0, 9.0, 1.0, 0.0, 0.0, 0.0])
    pair.add_edges([1], [0], measurement, information[None])
    adjoint = measurement.inverse().adjoint()[0]
    block = adjoint.T @ information @ adjoint
    projector = np.eye(6) - np.linalg.pinv(block) @ block
    share = unmeasured_share(pair)
    np.testing.assert_allclose(share[1], np.diag(projector), atol=1e-12)
    assert (share[1, :3] > 0.01).all() and (share[1, 3:] > 0.01).all()  # mixed
    np.testing.assert_array_equal(share[0], 0.0)  # held: the gauge
    assert unmeasured_directions(pair).tolist() == [0, 3]


def test_gauss_newton_on_a_singular_system_names_the_unmeasured_node():
    """Gauss-Newton has no damping, so a leaf seen only by a rotation-only edge makes its
    normal equations singular: the termination said the step raised the error, and now names
    the node."""
    graph, _ = _with_partial_leaf(SE3, "rotation")
    summary = posegraph.optimize(graph, options=posegraph.SolverOptions(method="gn")).summary
    assert not summary.converged
    assert summary.termination.startswith("normal equations singular")
    assert "(node 9999: 3 of its 6 directions)" in summary.termination


def test_covariances_of_a_graph_with_an_unmeasured_direction_can_be_refused():
    """A leaf of an SE2 graph seen by two position-only edges: where they disagree, the Log
    couples its heading to its position at second order, so H factorises, and ``marginals``
    gives the heading a variance that means nothing (over 1e5 rad² at the optimum). With
    ``require_measured`` it names the leaf instead."""
    graph, _ = _with_partial_leaf(SE2, "position")
    measurement = graph.values[6].between(graph.values[-1]).retract(np.full((1, 3), -0.02))
    graph.add_edges([graph.node_ids[6]], [9999], measurement, graph.edges.information[-1:])
    posegraph.optimize(graph)
    assert posegraph.marginals(graph, [9999])[0, 2, 2] > 1e5
    with pytest.raises(NotPositiveDefinite, match=r"nothing \(node 9999: 1 of its 3 directions\)"):
        posegraph.marginals(graph, [9999], require_measured=True)


@pytest.mark.parametrize(
    "group, joins",
    [(SE2, 1), (SE3, 1), (SE3, 2), (Sim3, 2)],
    ids=["SE2-1", "SE3-1", "SE3-2", "Sim3-2"],
)
def test_an_undetermined_direction_moves_a_part_of_the_map_without_changing_any_residual(
    group, joins
):
    """Two maps joined by position-only edges: by one, the second can turn about it; by two
    in 3D, about the line through them. The direction found is a rigid turn of the second map
    (its 20 nodes move, the first map's stay) that changes no measured residual Ω^½ r to first
    order with jr⁻¹ = I (``observability``'s docstring): against a generic direction's 17–43,
    at most 1e-10 (measured 1e-14). The true derivative, by central differences, adds
    (jr⁻¹(r) − I) J₀ δ, which is proportional to the residuals: 1e-9 here, 1.2e-4 for SE3 by
    two edges."""
    graph = maps_joined_by_positions(group, joins)
    direction = undetermined_direction(graph, graph.values)
    assert direction is not None
    moving = np.abs(direction).max(axis=1) > 1e-6
    np.testing.assert_array_equal(moving, graph.node_ids >= 1000)
    generic = np.random.default_rng(75).normal(size=direction.shape)
    generic[graph.gauge_nodes()] = 0.0
    root = information_root(graph.edges.information)  # what each edge measures: Ω^½ r
    edges = graph.edges
    met = np.zeros((len(edges), group.dof))
    jac_i, jac_j = np.split(between_jacobians(relative_poses(graph.values, edges), met), 2, axis=2)

    def first_order(tangent):
        change = jac_i @ tangent[edges.i, :, None] + jac_j @ tangent[edges.j, :, None]
        return np.abs(root @ change).max()

    def derivative(tangent, step=1e-6):
        ahead, behind = (graph.values.retract(s * tangent) for s in (step, -step))
        change = between_residuals(ahead, edges) - between_residuals(behind, edges)
        return np.abs(np.einsum("mij,mj->mi", root, change)).max() / (2 * step)

    assert first_order(direction) < 1e-10 and first_order(generic) > 1.0
    assert derivative(direction) < 1e-3 and derivative(generic) > 1.0


@pytest.mark.parametrize(
    "group, joins", [(SE2, 2), (SE3, 3), (Sim3, 3)], ids=["SE2", "SE3", "Sim3"]
)
def test_maps_joined_by_enough_position_only_edges_have_no_undetermined_direction(group, joins):
    """Two maps joined by two position-only edges in 2D, or three in 3D, cannot turn."""
    graph = maps_joined_by_positions(group, joins)
    assert undetermined_direction(graph, graph.values) is None


def test_a_graph_tied_by_full_rank_measurements_needs_no_factorisation(monkeypatch):
    """Nodes joined to a held node, or to a prior of full rank, by edges of full rank cannot
    move (``observability``'s docstring): ``tied_by_full_rank`` says so, and the test of
    undetermined directions then builds nothing, where factorising H₁ agrees. A loop measured by
    position only does not untie a chain of full rank. Position-only edges or priors tie
    nothing: there the factorisation decides, whichever way (a map held only by GNSS positions
    cannot turn; one hanging by two position-only edges in 3D can)."""
    chain = random_graph(SE3, 30, 5, seed=76)
    position_only = np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    chain.add_edge(14, 60, chain.values[2].between(chain.values[25]), position_only)
    fixed_by_gnss, _ = city_with_fixes(0.0, seed=0)  # fixes of full rank, no node held
    assert fixed_by_gnss.gauge_nodes().size == 0
    track, _ = gnss_track(SE2, heading=0.3, seed=0)  # position-only fixes
    posegraph.optimize(track)
    hanging, turning = maps_joined_by_positions(SE3, 3), maps_joined_by_positions(SE3, 2)
    cases = [(chain, True), (fixed_by_gnss, True), (track, False), (hanging, False)]
    for graph, tied in cases:
        assert tied_by_full_rank(graph) is tied
        assert factorised_direction(graph, monkeypatch) is None
    assert not tied_by_full_rank(turning)
    assert undetermined_direction(turning, turning.values) is not None

    def untouched(*args):
        raise AssertionError("H₁ was built")

    monkeypatch.setattr(observability, "first_order_information", untouched)
    for graph, _ in cases[:2]:
        assert undetermined_direction(graph, graph.values) is None


def test_covariances_of_a_map_that_can_turn_about_position_only_edges_can_be_refused():
    """Two SE3 maps joined by two position-only edges: the second can turn about the line
    through them. At the optimum, CHOLMOD factorised H with that turn's pivot at 3e-16 of its
    diagonal entry, rounding's scale (SuperLU did not), and gave it a variance of 5e13 that
    means nothing (2.3 at most when a third edge stops it). Such a pivot is now refused, and
    with ``require_measured`` the first-order test refuses the turn before any factorisation.
    No node has a direction of its own that nothing measures (``unmeasured_directions``):
    either way the turn is found over the whole graph, naming the nodes it moves."""
    graph = maps_joined_by_positions(SE3, 2)
    assert not unmeasured_directions(graph).any()
    moving = r"nothing \(nodes 1010, 1012, 1014, … \(20 nodes\) move together"
    for require_measured in (False, True):
        with pytest.raises(NotPositiveDefinite, match=moving):
            posegraph.marginals(graph, [1048], require_measured=require_measured)
    joined = maps_joined_by_positions(SE3, 3)
    assert posegraph.marginals(joined, [1048], require_measured=True)[0].max() < 10.0
