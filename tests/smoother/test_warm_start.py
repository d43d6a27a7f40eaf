"""The smoother's warm starts: reuse of the solution, the pattern and the linearisation; composed
new poses; restarts; pickling."""

from __future__ import annotations

import copy
import dataclasses
import pickle
import subprocess
import sys

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.benchmarks.incremental import stream
from posegraph.graph import PoseGraph
from posegraph.lie import SE2, SE3, Sim3
from posegraph.problem.linear import NormalEquations
from posegraph.robust.spec import robust_mask
from posegraph.smoother import COMPOSED, RESTART, SKIPPED
from posegraph.solvers import SolverOptions
from tests.smoother.helpers import count_normal_equations, drive_on, searched_from_decisions

from ..conftest import cull, random_graph


def _add_odometry(graph: PoseGraph, information: np.ndarray | None = None) -> None:
    last = int(graph.node_ids[-1])
    graph.add_node(last + 1)
    graph.add_edge(
        last,
        last + 1,
        SE2.from_xytheta([1.0, 0.0, 0.1]),
        np.eye(3) if information is None else information,
    )


def test_after_culling_keyframes_a_warm_start_ends_where_a_fresh_solve_does():
    """Keyframes culled from an optimised map (their neighbours re-linked), and a pose added:
    the warm start ends at a fresh solve's optimum, by least squares and by GNC, and is not
    taken for the old solution extended (the culled nodes' loops changed the problem). GNC's
    rejections stay with the edges that remain, its search starts from its decisions there,
    and it rejects what a fresh GNC rejects: the false loops that remain."""
    clean, _ = manhattan_world(200, seed=3)
    noisy, false = add_false_loops(clean, 0.1, seed=3)
    culled = [60, 94, 130]  # 94 ends a false loop
    ends = noisy.node_ids[noisy.edges.i], noisy.node_ids[noisy.edges.j]
    touching = np.isin(ends[0], culled) | np.isin(ends[1], culled)
    # The edges that remain come first, in order, then the re-links and the new odometry.
    remaining_false = np.flatnonzero(false[~touching])
    for graph, robust in ((clean, None), (noisy, "gnc")):
        smoother = posegraph.Smoother(graph)
        smoother.optimize(robust=robust)
        for node in culled:
            cull(smoother, node)
        rejected = np.flatnonzero(smoother.rejected()[0])
        assert rejected.tolist() == (remaining_false.tolist() if robust else [])
        graph.add_node(500)
        graph.add_edge(199, 500, SE2.from_xytheta([1.0, 0.0, 0.0]), np.eye(3) * 100)
        warm = copy.deepcopy(smoother).optimize(robust=robust).summary
        fresh = posegraph.optimize(graph.copy(), init="chordal", robust=robust).summary
        assert warm.initialization == "warm start" and warm.termination != COMPOSED
        assert searched_from_decisions(warm) == (robust is not None)
        assert warm.final_error == pytest.approx(fresh.final_error, rel=1e-6), robust
        assert warm.rejected_edges == fresh.rejected_edges
    assert (false & touching).any() and warm.rejected_edges == remaining_false.tolist()


@pytest.mark.parametrize("group", [SE2, SE3, Sim3])
def test_graphs_with_nothing_to_optimise(group):
    """An empty graph, and graphs whose every node is held, end at once with every
    initialisation and robust mode (the empty one raised IndexError in the spanning tree and
    chordal's solve), also when one grows by a prior after a solve (IndexError in the growth of
    its empty sparsity pattern)."""
    held = PoseGraph(group)
    held.add_nodes([0, 1], group.identity((2,)))
    held.add_edge(0, 1, group.exp(np.full(group.dof, 0.1)), np.eye(group.dof))
    held.fix([0, 1])
    single = PoseGraph(group)
    single.add_node(4, group.identity())
    for graph in (PoseGraph(group), held, single):
        for init in ("auto", "file", "odometry", "spanning-tree", "chordal"):
            result = posegraph.optimize(graph.copy(), init=init)
            assert result.summary.termination == "nothing to optimise"
        for robust in ("gnc", "huber"):
            assert posegraph.optimize(graph.copy(), robust=robust).summary.converged
    smoother = posegraph.Smoother(held)
    result = smoother.optimize()
    assert result.summary.final_error == pytest.approx(0.5 * 0.1**2 * group.dof)
    held.add_prior(0, group.exp(np.full(group.dof, 0.2)), np.eye(group.dof))
    grown = smoother.optimize().summary
    assert "sparsity pattern (grown)" in grown.reused
    assert grown.final_error == pytest.approx(0.5 * (0.1**2 + 0.2**2) * group.dof)
    assert posegraph.marginals(PoseGraph(group), []).shape == (0, group.dof, group.dof)


def test_nodes_added_without_values_are_composed_from_their_edges():
    graph, _ = manhattan_world(num_poses=60, seed=81)
    fresh = PoseGraph(SE2)
    fresh.add_node(0, graph.values[0])
    fresh.add_nodes(graph.node_ids[1:])
    fresh.add_edges(
        graph.node_ids[graph.edges.i],
        graph.node_ids[graph.edges.j],
        graph.edges.measurements,
        graph.edges.information,
    )
    with pytest.raises(ValueError, match="no values"):
        posegraph.optimize(fresh.copy(), init="file")
    result = posegraph.optimize(fresh)
    assert result.summary.converged
    assert result.summary.final_error == pytest.approx(
        posegraph.optimize(graph).summary.final_error, rel=1e-6
    )


def test_warm_starts_reuse_the_solution_and_then_the_structure():
    full, _ = manhattan_world(num_poses=300, seed=82)
    graphs = stream(full, 50)
    smoother = posegraph.Smoother(next(graphs))
    summaries = [smoother.optimize().summary]
    summaries += [smoother.optimize().summary for _ in graphs]
    assert summaries[0].initialization != "warm start"
    assert all(s.initialization == "warm start" for s in summaries[1:])
    assert all(s.reused and s.reused[0].startswith("previous solution") for s in summaries[1:])
    # Each step only appended nodes and edges: the pattern grows and the edges solved in the
    # previous call keep their linearisation (their nodes did not move since).
    assert all("sparsity pattern (grown)" in s.reused for s in summaries[1:])
    assert all(any(r.startswith("linearization of") for r in s.reused) for s in summaries[1:])
    scratch = posegraph.optimize(full.copy()).summary.final_error
    assert summaries[-1].final_error == pytest.approx(scratch, rel=1e-6)
    assert np.mean([s.num_iterations for s in summaries[1:]]) < np.mean(
        [summaries[0].num_iterations, 4]
    )


def test_new_poses_that_hang_off_the_solution_by_a_tree_are_composed_without_a_solve(
    monkeypatch,
):
    """A back end adds poses with their odometry alone: the solution, with each new pose composed
    from its neighbour, is already optimal (the new edges' residuals are zero and the rest is
    unchanged), so no linear system is built. A pose given a value is composed too. A solve
    from there and one from scratch agree, and so do the covariances."""
    graph, _ = manhattan_world(num_poses=120, seed=89)
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize()
    solution, last = graph.values, int(graph.node_ids[-1])
    step, back = SE2.from_xytheta([1.0, 0.1, 0.05]), SE2.from_xytheta([-0.8, 0.3, -0.2])
    graph.add_node(last + 1)
    graph.add_edge(last, last + 1, step, np.diag([50.0, 50.0, 200.0]))
    graph.add_node(last + 2, SE2.from_xytheta([5.0, 5.0, 1.0]))  # replaced: not the optimum
    graph.add_edge(last + 2, last + 1, back, np.array([[40.0, 5, 1], [5, 30, 2], [1, 2, 90]]))
    built = count_normal_equations(monkeypatch)
    result = smoother.optimize()
    summary = result.summary
    assert built == [] and summary.termination == COMPOSED and summary.converged
    assert summary.num_iterations == 0 and summary.initialization == "warm start"
    assert graph.values[:120].same_as(solution)
    np.testing.assert_allclose(
        graph.matrices([last + 1, last + 2]),
        [(solution[-1] @ step).as_matrix(), (solution[-1] @ step @ back.inverse()).as_matrix()],
        atol=1e-12,
    )
    assert summary.final_error == pytest.approx(first.summary.final_error, rel=1e-12)
    again = posegraph.optimize(graph.copy(), init="file").summary  # a solve from there
    assert again.num_iterations <= 1 and again.num_variables == summary.num_variables
    assert summary.phase_times.keys() == again.phase_times.keys()
    assert again.final_error == pytest.approx(summary.final_error, rel=1e-12)
    scratch = posegraph.optimize(graph.copy(), init="chordal").summary.final_error
    assert summary.final_error <= scratch * (1 + 1e-9)
    np.testing.assert_allclose(
        posegraph.marginals(smoother, [last + 2]),
        posegraph.marginals(graph.copy(), [last + 2]),
        rtol=1e-10,
    )
    restored = pickle.loads(pickle.dumps(smoother))  # no cached system, the same solution
    restored.graph.add_node(last + 3)
    restored.graph.add_edge(last + 2, last + 3, step, np.eye(3))
    assert restored.optimize().summary.termination == COMPOSED


@pytest.mark.parametrize(
    "change",
    [
        "a loop",
        "an edge removed",
        "a prior",
        "a prior replaced",
        "a held pose",
        "a held pose released",
        "a pose alone",
        "a position-only edge",
        "moved values",
        "a solve stopped early",
        "a robust solve",
    ],
)
def test_a_solve_follows_where_a_tree_of_new_poses_is_not_all_that_changed(change):
    """The solution extends to the new poses only if nothing else changed: otherwise the warm
    start solves, and ends where a fresh solve does."""
    graph, _ = manhattan_world(num_poses=60, seed=90)
    if change == "a held pose released":
        graph.fix([30])  # at the generator's start value, off the optimum
    if change == "a prior replaced":
        graph.add_prior(0, graph.values[0], np.eye(3))
    smoother = posegraph.Smoother(graph)
    smoother.optimize(
        options=posegraph.SolverOptions(max_iterations=1)
        if change == "a solve stopped early"
        else None,
        robust="huber" if change == "a robust solve" else None,
    )
    last = int(graph.node_ids[-1])
    if change == "an edge removed":  # and one more added: the new edges' count fits a tree
        smoother.remove_edges([np.flatnonzero(robust_mask(graph, "loops"))[0]])
    _add_odometry(graph, np.diag([1.0, 1.0, 0.0]) if change == "a position-only edge" else None)
    if change in ("a loop", "an edge removed"):
        graph.add_edge(int(graph.node_ids[0]), last + 1, SE2.identity(), np.eye(3))
    elif change == "a prior":
        graph.add_prior(last + 1, SE2.from_xytheta([0.0, 0.0, 0.0]), np.eye(3))
    elif change == "a prior replaced":  # as a caller may, in place: the count stays
        moved = graph.priors.measurements.retract(np.full((1, 3), 0.5))
        graph.priors = dataclasses.replace(graph.priors, measurements=moved)
    elif change == "a held pose":
        graph.fix([last + 1])
    elif change == "a held pose released":
        graph.fix([30], fixed=False)
    elif change == "a pose alone":
        graph.add_node(last + 2, SE2.identity())
    elif change == "moved values":
        graph.set_values(graph.values.retract(np.full((graph.num_nodes, 3), 1e-3)))
    result = smoother.optimize()
    assert result.summary.termination != COMPOSED and result.summary.num_variables > 0
    scratch = posegraph.optimize(graph.copy(), init="chordal").summary.final_error
    assert result.summary.final_error == pytest.approx(scratch, rel=1e-6)


def test_a_warm_start_restarts_when_new_loops_disagree_with_the_solution():
    """With rotations this noisy (σ = 0.4 rad per edge), the optimum of the first rings can sit
    in another basin than the optimum once later rings close their loops: solving on from it
    stalled at 419.6, where the graph's optimum is 322.4. The new loops then fail the χ² test
    against the previous solution, and the values restart from chordal relaxation."""
    full, truth = sphere(rings=8, poses_per_ring=16, rotation_sigma=0.4, translation_sigma=0.4)
    graphs = stream(full, 16)
    smoother = posegraph.Smoother(next(graphs))
    summaries = [smoother.optimize().summary]
    summaries += [smoother.optimize().summary for _ in graphs]
    assert RESTART in [s.initialization for s in summaries[1:]]
    assert "warm start" in [s.initialization for s in summaries[1:]]
    from_truth = full.copy()
    from_truth.set_values(truth)
    best = posegraph.optimize(from_truth, init="file").summary.final_error
    assert summaries[-1].final_error == pytest.approx(best, rel=1e-6)


def test_only_new_measurements_that_disagree_restart_a_least_squares_warm_start():
    graph, _ = manhattan_world(num_poses=120, seed=87)
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    loops = np.flatnonzero(np.abs(graph.edges.j - graph.edges.i) > 1)
    smoother.remove_edges(loops[:3])  # the solution still suits the measurements that remain
    assert smoother.optimize().summary.initialization == "warm start"
    robust = copy.deepcopy(smoother)
    for g in (graph, robust.graph):  # a loop 30 m and 2 rad away from what the map says
        g.add_edge(0, 60, SE2.from_xytheta([30.0, 0.0, 2.0]), np.eye(3) * 100)
    assert smoother.optimize().summary.initialization == RESTART
    # A robust solve keeps its warm start: chordal relaxation would spread an outlier's pull.
    assert robust.optimize(robust="gnc").summary.initialization == "warm start"


def test_the_restarts_chi2_test_counts_the_directions_a_measurement_weighs():
    """A prior 15 Mahalanobis units² from the solution is consistent as a full SE2 prior
    (χ²₃(0.999) = 16.3) but not as a position-only one (χ²₂(0.999) = 13.8): counted as 3
    degrees of freedom, the position-only prior kept its warm start."""
    initializations = []
    for information in (np.eye(3), np.diag([1.0, 1.0, 0.0])):
        graph, _ = manhattan_world(num_poses=120, seed=87)
        smoother = posegraph.Smoother(graph)
        smoother.optimize()
        off = graph.values_of([60]) @ SE2.from_xytheta([np.sqrt(15.0), 0.0, 0.0])
        graph.add_prior(60, off, information)
        initializations.append(smoother.optimize().summary.initialization)
    assert initializations == ["warm start", RESTART]


def test_a_smoother_and_its_result_pickle_and_warm_start_alike():
    """A back end checkpoints its smoother, or hands it to another process, after optimising.
    The CHOLMOD handles of the solver cache cannot be pickled, so they are left out: the copy
    warm-starts from the same values to the same optimum, building its system anew."""
    graph, _ = manhattan_world(num_poses=120, seed=86)
    smoother = posegraph.Smoother(graph)
    result = smoother.optimize()
    copies = [pickle.loads(pickle.dumps(smoother)), copy.deepcopy(smoother)]
    for restored in copies:
        assert restored.last_system("auto") is None and restored.optimized
        assert restored.graph.values.same_as(graph.values)
    np.testing.assert_array_equal(
        pickle.loads(pickle.dumps(result)).values.as_matrix(), result.values.as_matrix()
    )
    assert copy.deepcopy(result).summary == result.summary
    corrupted, _ = add_false_loops(graph, 0.1, seed=0)  # GNC's result carries its leverages
    robust = posegraph.optimize(corrupted, robust="gnc")
    assert robust.leverage is not None
    for restored in (pickle.loads(pickle.dumps(robust)), copy.deepcopy(robust)):
        assert restored.leverage is None and restored.summary == robust.summary
    summaries = []
    for s in [smoother, *copies]:
        g = s.graph
        first, last = int(g.node_ids[0]), int(g.node_ids[-1])
        g.add_edge(first, last, g.values[0].between(g.values[-1]), np.eye(3))
        summaries.append(s.optimize().summary)
    assert all(s.initialization == "warm start" for s in summaries)
    assert "sparsity pattern (grown)" in summaries[0].reused
    assert not any(r.startswith("sparsity") for s in summaries[1:] for r in s.reused)
    assert all(
        s.final_error == pytest.approx(summaries[0].final_error, rel=1e-9) for s in summaries
    )


def test_unchanged_structure_reuses_pattern_and_symbolic_factorization():
    graph = random_graph(SE2, 40, 20, seed=83, noise=0.1)
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize()
    graph.set_values(
        graph.values.retract(np.random.default_rng(84).normal(scale=0.05, size=(40, 3)))
    )
    second = smoother.optimize()
    assert (
        "sparsity pattern" in second.summary.reused
        and "symbolic factorization" in second.summary.reused
    )
    assert not any(r.startswith("linearization") for r in second.summary.reused)  # nodes moved
    assert second.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-6)
    again = smoother.optimize()  # nothing changed: the solution stands, with no solve
    assert again.summary.termination == COMPOSED and again.values.same_as(second.values)
    assert again.summary.final_error == second.summary.final_error
    graph.add_edge(
        graph.node_ids[0], graph.node_ids[30], graph.values[0].between(graph.values[30]), np.eye(3)
    )
    third = smoother.optimize()
    assert "sparsity pattern" not in third.summary.reused  # the structure changed
    assert "sparsity pattern (grown)" in third.summary.reused  # by an appended edge
    # The edges solved before keep their linearisation: their nodes have not moved since.
    assert f"linearization of {graph.num_edges - 1} edges" in third.summary.reused
    smoother.remove_edges([graph.num_edges - 1])
    fourth = smoother.optimize()
    assert not any(r.startswith("sparsity pattern") for r in fourth.summary.reused)
    assert not any(r.startswith("linearization") for r in fourth.summary.reused)
    assert fourth.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-6)


def test_irls_calls_reuse_the_last_system_and_linearisation_as_least_squares_calls_do():
    """An IRLS kernel's warm call keeps its normal equations and linearisation for the next:
    the weights are taken anew from the reused residuals, so it ends where a call that rebuilds
    everything (on a copy, which drops them) ends."""
    graph = random_graph(SE2, 40, 20, seed=83, noise=0.1)
    smoother = posegraph.Smoother(graph)
    smoother.optimize(robust="cauchy")
    rebuilt = copy.deepcopy(smoother).optimize(robust="cauchy")
    again = smoother.optimize(robust="cauchy")
    assert not any(r.startswith(("sparsity", "linearization")) for r in rebuilt.summary.reused)
    assert {"sparsity pattern", "symbolic factorization"} <= set(again.summary.reused)
    assert f"linearization of {graph.num_edges} edges" in again.summary.reused
    assert again.summary.final_error == pytest.approx(rebuilt.summary.final_error, rel=1e-12)
    drive_on(graph, 3)
    grown = smoother.optimize(robust="cauchy")
    assert "sparsity pattern (grown)" in grown.summary.reused
    assert f"linearization of {graph.num_edges - 3} edges" in grown.summary.reused


def test_streamed_calls_finish_with_the_last_factorisation_and_end_where_batch_ends(monkeypatch):
    """Streamed one pose per call, a sphere's loop-closing calls end on a chord step: after a
    Newton step, the factorisation that gave it predicts that one more step from it finishes,
    and that step is taken without factorising again (fewer factorisations than accepted
    steps). The last call ends where a tightly converged solve does: its error within 1e-6
    relative, its values within 1e-3 (what the default tolerance, 1e-7 of the error, leaves
    along the sphere's weakest directions: 1e-4 with or without chord steps)."""
    full, _ = sphere(rings=6, poses_per_ring=16)
    factorisations = []
    factorize = NormalEquations.factorize

    def counted_factorize(self, data, damping=None):
        factorisations.append(damping)
        factorize(self, data, damping)

    monkeypatch.setattr(NormalEquations, "factorize", counted_factorize)
    graphs = stream(full, 1)
    smoother, finished_on_chords = posegraph.Smoother(next(graphs)), 0
    for _ in graphs:
        before = len(factorisations)
        result = smoother.optimize()
        accepted = sum(record.accepted for record in result.summary.iterations)
        assert result.summary.converged
        finished_on_chords += 0 < len(factorisations) - before < accepted
    monkeypatch.undo()
    assert finished_on_chords >= 10
    tight = posegraph.optimize(
        full.copy(), options=posegraph.SolverOptions(relative_decrease=1e-14)
    )
    assert result.summary.final_error == pytest.approx(tight.summary.final_error, rel=1e-6)
    streamed = smoother.graph.values_of(full.node_ids)
    np.testing.assert_allclose(tight.values.local(streamed), 0.0, atol=1e-3)


@pytest.mark.parametrize("step", [1, 10])
def test_a_stream_with_cholmod_never_imports_scipy(step):
    """Importing scipy's subpackages costs 0.3–0.4 s: a back end streaming an SE2 graph with
    loop closures into a Smoother with CHOLMOD, from its first pose on (a first call of one pose
    has no edge to compose along, one of ten composes along a spanning tree), does without
    them."""
    pytest.importorskip("cvxopt")
    probe = (
        "import sys\n"
        "from posegraph_datasets.generators import manhattan_world\n"
        "from posegraph.benchmarks.incremental import stream\n"
        "from posegraph.smoother import Smoother\n"
        "full = manhattan_world(num_poses=60, seed=1)[0]\n"
        "smoother = None\n"
        f"for graph in stream(full, {step}):\n"
        "    smoother = smoother or Smoother(graph)\n"
        "    smoother.optimize()\n"
        "print(smoother.graph.num_nodes, smoother.graph.num_edges)\n"
        "print(' '.join(sorted(sys.modules)))"
    )
    lines = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    nodes, edges = map(int, lines[0].split())
    assert nodes == 60 and edges > nodes - 1  # it closed loops
    assert not {name for name in lines[1].split() if name.split(".")[0] == "scipy"}


def test_calls_that_skip_their_solve_stay_within_the_share_asked_of_each_prefix_optimum():
    """Streamed with ``skip_within`` 5%, many calls skip their solve, and after every call the
    cost at the smoother's values exceeds the optimum of the graph so far (solved from scratch)
    by at most 5% of it; a call with the defaults then solves, ending at the batch optimum.
    With the defaults throughout, no call skips."""
    full, _ = manhattan_world(num_poses=300, seed=6)
    lazy = SolverOptions(skip_within=0.05)
    smoother, skipped = None, 0
    for graph in stream(full, 1):
        smoother = smoother or posegraph.Smoother(graph)
        result = smoother.optimize(options=lazy)
        skipped += result.summary.termination.startswith(SKIPPED)
        if graph.num_edges > graph.num_nodes:  # loops: an optimum above zero
            optimum = posegraph.optimize(graph.copy()).summary.final_error
            assert result.summary.final_error == pytest.approx(
                0.5 * posegraph.problem.factors.chi2(graph.values, graph.edges, graph.priors)
            )
            assert result.summary.final_error <= 1.05 * optimum * (1 + 1e-9)
    assert skipped > 50
    final = smoother.optimize()
    assert not final.summary.termination.startswith(SKIPPED)
    batch = posegraph.optimize(full.copy()).summary.final_error
    assert final.summary.final_error == pytest.approx(batch, rel=1e-6)
    eager = None
    for graph in stream(full, 1):
        eager = eager or posegraph.Smoother(graph)
        assert not eager.optimize().summary.termination.startswith(SKIPPED)


def test_a_removal_makes_the_next_call_solve_even_where_it_may_skip():
    """After a removal the solution's bound is unknown (``Solution.debt`` None): the next call
    solves, however large ``skip_within`` is."""
    full, _ = manhattan_world(num_poses=80, seed=1)
    graph = full.copy()
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    assert smoother.solution.debt == 0.0
    smoother.remove_edges([graph.num_edges - 1])
    assert smoother.solution.debt is None
    result = smoother.optimize(options=SolverOptions(skip_within=0.5))
    assert not result.summary.termination.startswith(SKIPPED)
    assert smoother.solution.debt == 0.0


def test_skip_within_must_be_a_finite_share():
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="skip_within"):
            SolverOptions(skip_within=bad)


def test_a_composed_call_keeps_the_last_runs_weights_and_weighs_what_it_appended_one():
    """GNC rejects the false loops; an odometry pose appended then leaves the decisions
    standing and solves nothing: the weights are the run's (0 on every false loop), then 1 for
    the new edge, as ``Solution.weights_for`` finds by comparing the edge sets."""
    clean, _ = manhattan_world(120, seed=2)
    graph, false = add_false_loops(clean, 0.1, seed=2)
    smoother = posegraph.Smoother(graph)
    smoother.optimize(robust="gnc")
    before = smoother.weights()[0]
    assert not before[false].any() and false.any()
    _add_odometry(graph)
    result = smoother.optimize(robust="gnc")
    assert result.summary.termination == COMPOSED
    edge_weights, prior_weights = smoother.weights()
    np.testing.assert_array_equal(edge_weights, np.append(before, 1.0))
    expected = smoother.solution.weights_for(graph.edges, graph.priors)
    np.testing.assert_array_equal(edge_weights, expected[0])
    np.testing.assert_array_equal(prior_weights, expected[1])
