"""Deleted residuals and innovations against what leaving out or adding an edge actually does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere
from posegraph_datasets.monocular import monocular_sequence

from posegraph.graph import odometry_mask
from posegraph.lie import SE3
from posegraph.problem.backends import available_backends, inverts_selectively
from posegraph.problem.factors import between_squares
from posegraph.robust import leverage as leverage_module
from posegraph.robust.leverage import Leverage, deleted_residuals, innovations
from posegraph.solvers import SolverOptions, solve

from ..conftest import random_graph

GRAPHS = {
    "SE2": lambda: manhattan_world(num_poses=150, seed=2)[0],
    "SE3": lambda: sphere(rings=4, poses_per_ring=10, seed=2)[0],
    "SE3-priors": lambda: random_graph(SE3, 40, 20, seed=3, noise=0.2, priors=3),
}
WITH_SIM3 = {**GRAPHS, "Sim3": lambda: monocular_sequence(150, drift=0.002, seed=2).sim3_graph()}
"""Sim3 adds a monocular sequence with scale drift (only for the exact joint innovations: the
probe estimates of its loops' deleted residuals are 12% off with 10,000 probes)."""
pytestmark = pytest.mark.parametrize("backend", available_backends())
on_graphs = pytest.mark.parametrize("make_graph", GRAPHS.values(), ids=GRAPHS.keys())


def _loops(graph):
    return np.flatnonzero(~odometry_mask(graph))[:8]


@on_graphs
def test_deleted_residual_is_the_cost_that_leaving_the_edge_out_saves(make_graph, backend):
    """At the optimum, against re-solving without edge e: d²ₑ equals χ²(all edges) −
    χ²(without e), for every edge from ``Leverage`` (exact with CHOLMOD, from many probes with
    SuperLU) and exactly for chosen edges; and the exact predicted s of e equals its s at the
    re-solved optimum. Up to the estimate's sampling error and the nonlinearity."""
    graph = make_graph()
    options = SolverOptions(linear_solver=backend)
    solution = solve(graph, options)
    loops = _loops(graph)
    leverage = Leverage(graph, solution.values, probes=10000, seed=1, linear_solver=backend)
    estimated = leverage.deleted_residuals
    exact = deleted_residuals(graph, solution.values, edges=loops, linear_solver=backend)
    for k, edge in enumerate(loops):
        keep = np.ones(graph.num_edges, dtype=bool)
        keep[edge] = False
        without = graph.with_edges(keep)
        without.set_values(solution.values)
        refit = solve(without, options)
        saved = solution.summary.final_chi2 - refit.summary.final_chi2
        assert estimated.innovation[edge] == pytest.approx(saved, rel=0.1, abs=0.1)
        assert exact.innovation[k] == pytest.approx(saved, rel=0.05, abs=0.05)
        squares = between_squares(refit.values, graph.edges)[edge]
        assert exact.squares[k] == pytest.approx(squares, rel=0.05, abs=0.05)


def test_exact_deleted_residuals_of_all_edges_at_once_equal_each_alone(backend):
    """The exact deleted residuals of every edge at once (with CHOLMOD by selected inversion)
    equal those of each edge chosen alone (by solves), priors and a held node included."""
    graph = GRAPHS["SE3-priors"]()
    graph.fixed[3] = True
    solution = solve(graph, SolverOptions(linear_solver=backend))
    every = deleted_residuals(graph, solution.values, linear_solver=backend)
    at_held = np.flatnonzero((graph.edges.i == 3) | (graph.edges.j == 3))
    assert at_held.size > 0
    for edge in np.union1d(np.arange(0, graph.num_edges, 7), at_held):
        alone = deleted_residuals(graph, solution.values, edges=[edge], linear_solver=backend)
        assert every.innovation[edge] == pytest.approx(alone.innovation[0], rel=1e-9)
        assert every.squares[edge] == pytest.approx(alone.squares[0], rel=1e-9)


@on_graphs
def test_a_solve_lends_its_normal_equations_to_the_deleted_residuals_at_its_solution(
    make_graph, backend, monkeypatch
):
    """Given the solve that ended at the values, the deleted residuals reuse its pattern, H and
    Jacobians (no new normal equations are built) and equal those computed anew; a solve of
    another structure lends nothing."""
    graph = make_graph()
    solution = solve(graph, SolverOptions(linear_solver=backend))
    anew = deleted_residuals(graph, solution.values, linear_solver=backend)
    with monkeypatch.context() as patched:
        patched.setattr(leverage_module, "NormalEquations", None)  # building one would raise
        lent = deleted_residuals(graph, solution.values, linear_solver=backend, solved=solution)
    np.testing.assert_allclose(lent.innovation, anew.innovation, rtol=1e-9)
    np.testing.assert_allclose(lent.squares, anew.squares, rtol=1e-9)
    np.testing.assert_allclose(lent.redundancy, anew.redundancy, rtol=1e-9, atol=1e-12)
    fewer = graph.with_edges(np.arange(graph.num_edges) != _loops(graph)[0])
    other = deleted_residuals(fewer, solution.values, linear_solver=backend, solved=solution)
    alone = deleted_residuals(fewer, solution.values, linear_solver=backend)
    np.testing.assert_allclose(other.innovation, alone.innovation, rtol=1e-9)


@on_graphs
def test_innovation_is_the_cost_that_adding_the_edge_adds(make_graph, backend):
    """At the optimum of the graph without some loops, each left-out loop's innovation χ²
    (exact: fewer columns than the probes) equals χ²(with e) − χ²(without) from re-solving
    with e."""
    graph = make_graph()
    options = SolverOptions(linear_solver=backend)
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[_loops(graph)] = True
    without = graph.with_edges(~left_out)
    solution = solve(without, options)
    exact = innovations(
        without, solution.values, graph.edges.subset(left_out), linear_solver=backend
    )
    for k, edge in enumerate(np.flatnonzero(left_out)):
        keep = ~left_out
        keep[edge] = True
        added = graph.with_edges(keep)
        added.set_values(solution.values)
        cost = solve(added, options).summary.final_chi2 - solution.summary.final_chi2
        assert exact[k] == pytest.approx(cost, rel=0.05, abs=0.05)


@pytest.mark.parametrize(
    "make_graph",
    [
        lambda: manhattan_world(num_poses=400, seed=2)[0],
        lambda: sphere(rings=6, poses_per_ring=12, seed=2)[0],
    ],
    ids=["SE2", "SE3"],
)
def test_innovations_beyond_the_probes_are_estimated_near_the_exact_ones(
    make_graph, backend, monkeypatch
):
    """With every loop left out, and their d columns in all one more than the probes (and,
    for CHOLMOD, than ``SELECTED_COLUMNS``), the innovations come from the probes: against the
    exact ones (one probe more), within a median of 5% and at most 25% (measured: 3–4% and
    15–21%)."""
    graph, without, solution, candidates = _loops_left_out(make_graph, backend)
    columns = len(candidates) * graph.group.dof
    monkeypatch.setattr(leverage_module, "SELECTED_COLUMNS", columns - 1)

    def innovations_with(probes: int) -> np.ndarray:
        leverage = Leverage(without, solution.values, probes, seed=1, linear_solver=backend)
        return leverage.innovations(candidates)

    estimated, exact = innovations_with(columns - 1), innovations_with(columns)
    error = np.abs(estimated - exact) / exact
    assert np.median(error) < 0.05
    assert error.max() < 0.25


@pytest.mark.parametrize(
    "make_graph",
    [
        lambda: manhattan_world(num_poses=400, seed=2)[0],
        lambda: sphere(rings=6, poses_per_ring=12, seed=2)[0],
    ],
    ids=["SE2", "SE3"],
)
def test_innovations_by_selected_inversion_equal_those_of_one_wide_solve(make_graph, backend):
    """Beyond the probes' width, within ``SELECTED_COLUMNS``, CHOLMOD's innovations come from
    selected inversion on H's pattern with the candidates' node pairs added: they equal those
    of the solve with every candidate's columns (one probe more) to 1e-8 relative."""
    if not inverts_selectively(backend):
        pytest.skip(f"{backend} does not invert selectively: it estimates these innovations")
    graph, without, solution, candidates = _loops_left_out(make_graph, backend)
    columns = len(candidates) * graph.group.dof
    assert columns <= leverage_module.SELECTED_COLUMNS

    def innovations_with(probes: int) -> np.ndarray:
        leverage = Leverage(without, solution.values, probes, seed=1, linear_solver=backend)
        return leverage.innovations(candidates)

    np.testing.assert_allclose(innovations_with(columns - 1), innovations_with(columns), rtol=1e-8)


def _loops_left_out(make_graph, backend):
    """A graph, the graph without its loops, that one's solution, and the loops."""
    graph = make_graph()
    left_out = ~odometry_mask(graph)
    without = graph.with_edges(~left_out)
    solution = solve(without, SolverOptions(linear_solver=backend))
    return graph, without, solution, graph.edges.subset(left_out)


@pytest.mark.parametrize("make_graph", WITH_SIM3.values(), ids=WITH_SIM3.keys())
def test_sequential_innovations_sum_to_the_cost_that_adding_the_edges_together_adds(
    make_graph, backend
):
    """At the optimum of the graph without some loops (one end of the first held fixed, so
    that a candidate meets a node with no columns in H), the running sums of the loops'
    sequential innovations equal χ²(with the first k) − χ²(without), from re-solving. They are
    exact, so only the nonlinearity separates them."""
    graph = make_graph()
    options = SolverOptions(linear_solver=backend)
    loops = _loops(graph)
    graph.fixed[graph.edges.i[loops[0]]] = True
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[loops] = True
    without = graph.with_edges(~left_out)
    solution = solve(without, options)
    leverage = Leverage(without, solution.values, linear_solver=backend)
    candidates = graph.edges.subset(loops)
    joint = np.cumsum(leverage.sequential_innovations(candidates))
    costs = []
    for k in range(1, loops.size + 1):
        keep = ~left_out
        keep[loops[:k]] = True
        added = graph.with_edges(keep)
        added.set_values(solution.values)
        costs.append(solve(added, options).summary.final_chi2 - solution.summary.final_chi2)
    assert joint == pytest.approx(costs, rel=0.02, abs=0.05)


def test_candidates_beyond_double_precision_have_infinite_innovations(backend):
    """A candidate whose measurement overflowed: its joint innovations are ∞ (as its single
    innovation is), so a search that weighs it adds nothing rather than failing."""
    graph = GRAPHS["SE3"]()
    solution = solve(graph, SolverOptions(linear_solver=backend))
    candidates = graph.edges.subset(_loops(graph)[:2])
    measured = candidates.measurements
    candidates = dataclasses.replace(
        candidates,
        measurements=SE3(measured.rotation, np.full_like(measured.translation, np.inf)),
    )
    leverage = Leverage(graph, solution.values, linear_solver=backend)
    assert np.isposinf(leverage.sequential_innovations(candidates)).all()
    assert np.isposinf(leverage.innovations(candidates)).all()


def test_no_candidates_have_no_innovations(backend):
    """Innovations and joint innovations of no candidate edges are empty (the exact path
    solves for zero columns)."""
    graph = GRAPHS["SE3"]()
    solution = solve(graph, SolverOptions(linear_solver=backend))
    leverage = Leverage(graph, solution.values, linear_solver=backend)
    none = graph.edges.subset(np.array([], dtype=np.int64))
    assert leverage.innovations(none).shape == (0,)
    assert leverage.sequential_innovations(none).shape == (0,)


def test_innovations_of_the_same_candidates_are_computed_once(backend, monkeypatch):
    """A second call with equal candidates (another EdgeSet of the same edges) returns the
    first call's innovations without computing them again; other candidates, or the same
    edges with other information, are computed."""
    graph = GRAPHS["SE2"]()
    solution = solve(graph, SolverOptions(linear_solver=backend))
    loops = _loops(graph)
    keep = np.ones(graph.num_edges, dtype=bool)
    keep[loops] = False
    without = graph.with_edges(keep)
    leverage = Leverage(without, solution.values, linear_solver=backend)
    computed = []
    original = Leverage._computed_innovations
    monkeypatch.setattr(
        Leverage,
        "_computed_innovations",
        lambda self, candidates: computed.append(len(candidates)) or original(self, candidates),
    )
    first = leverage.innovations(graph.edges.subset(loops))
    again = leverage.innovations(graph.edges.subset(loops.copy()))
    np.testing.assert_array_equal(first, again)
    assert computed == [loops.size]
    leverage.innovations(graph.edges.subset(loops[:3]))
    heavier = graph.edges.subset(loops)
    heavier = dataclasses.replace(heavier, information=2.0 * heavier.information)
    assert np.all(leverage.innovations(heavier) > first)
    assert computed == [loops.size, 3, loops.size]


def test_leverage_serves_only_its_own_measurements_at_its_own_values(backend):
    """``serves`` holds for a copy of the graph at equal values, and fails for moved values,
    one edge left out, or one edge's information scaled."""
    graph = GRAPHS["SE3-priors"]()
    solution = solve(graph, SolverOptions(linear_solver=backend))
    leverage = Leverage(graph, solution.values, linear_solver=backend)
    assert leverage.serves(graph.copy(), solution.values[np.arange(graph.num_nodes)])
    assert not leverage.serves(graph, solution.values.retract(np.full((graph.num_nodes, 6), 1e-9)))
    keep = np.ones(graph.num_edges, dtype=bool)
    keep[-1] = False
    assert not leverage.serves(graph.with_edges(keep), solution.values)
    weights = np.ones(graph.num_edges)
    weights[0] = 1.5
    assert not leverage.serves(graph.weighted(weights), solution.values)
