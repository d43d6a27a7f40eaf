"""GNC's runs from the start that calibration asks for. The second opinion at a narrower width:
asked only where GNC's solution fits the median loop closure worse than its start did, taken
only where its TLS objective at the file's information is lower, and the graph's information
left as it was otherwise. GNC anew at a calibrated width: taken only where its TLS objective is
lower than the settled solution's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world

import posegraph
from posegraph.init.choice import initialize
from posegraph.robust import calibration, second_opinion
from posegraph.robust.spec import RobustSpec, resolve


@pytest.fixture(scope="module")
def problem():
    """A manhattan world, GNC's kernel on it, its odometry start and least-squares solution,
    and a solution bent away from both (every pose turned a little more than the last)."""
    graph, _ = manhattan_world(num_poses=300, seed=5)
    kernel = resolve(RobustSpec.parse("gnc", "loops", False), graph)
    start = initialize(graph, "odometry")
    solved = posegraph.optimize(graph.copy())
    return graph, kernel, start, solved, _turned(solved, 0.002)


def _turned(result, radians: float):
    """``result`` with each pose turned by ``radians`` more than the one before."""
    twist = np.zeros((len(result.values), 3))
    twist[:, 2] = radians * np.arange(len(twist))
    values = result.values.compose(type(result.values).exp(twist))
    return dataclasses.replace(result, values=values)


def _runs(graph, kernel, start, values, seen, searched=None):
    """GNC's runs from ``start`` on ``graph``, scripted to end at ``values``, and a search from
    an earlier run's decisions, at ``searched``; each records the information and the values
    it starts from, whether it searches, and the run whose decisions it searches from."""

    def solve(after=None, search: bool = True, stage: str = "calibrated"):
        seen.append((graph.edges.information, graph.values, search, after))
        return values if after is None else searched

    return second_opinion.FromStart(graph, kernel, start, solve)


def test_a_solution_that_fits_the_median_loop_worse_than_its_start_asks_for_it(problem):
    graph, kernel, start, solved, bent = problem
    measured = kernel.measured[: graph.num_edges]
    assert second_opinion.fits_median_worse(graph, measured, start, bent.values)
    assert not second_opinion.fits_median_worse(graph, measured, start, solved.values)
    assert not second_opinion.fits_median_worse(graph, np.zeros_like(measured), start, bent.values)


def test_the_narrower_run_replaces_a_worse_solution_and_keeps_its_precision(problem):
    graph, kernel, start, solved, bent = problem
    work, seen = graph.copy(), []
    taken = _runs(work, kernel, start, solved, seen).second_opinion(bent)
    assert taken is not None and taken[0] is solved
    assert taken[1] == second_opinion.NARROWER
    ((information, values, searched, after),) = seen
    narrower = second_opinion.NARROWER * graph.edges.information  # every precision
    assert np.allclose(information, narrower, rtol=1e-12, atol=0)
    assert np.allclose(values.as_matrix(), start.as_matrix())  # GNC anew from the start
    assert searched and after is None  # with its local search, before the objectives compare
    assert np.allclose(work.edges.information, narrower, rtol=1e-12, atol=0)


def test_a_narrower_run_that_ends_worse_leaves_the_information_as_it_was(problem):
    graph, kernel, start, solved, bent = problem
    work, seen = graph.copy(), []
    edges, priors = work.edges, work.priors
    worse = _turned(bent, 0.01)
    taken = _runs(work, kernel, start, worse, seen).second_opinion(bent)
    assert taken is None and len(seen) == 1
    assert work.edges is edges and work.priors is priors


def _rejecting(result, edges: list[int]):
    """``result`` as a robust run that rejected ``edges``."""
    return dataclasses.replace(
        result, summary=dataclasses.replace(result.summary, rejected_edges=edges)
    )


def test_a_solution_that_fits_the_median_loop_better_and_rejected_some_is_not_second_guessed(
    problem,
):
    graph, kernel, start, solved, _ = problem
    work, seen = graph.copy(), []
    loop = int(np.flatnonzero(kernel.measured)[0])
    taken = _runs(work, kernel, start, solved, seen).second_opinion(_rejecting(solved, [loop]))
    assert taken is None and seen == []


@pytest.mark.parametrize(("turn", "taken"), [(5e-4, True), (1e-4, False)])
def test_a_solution_that_kept_every_loop_is_judged_by_the_median_loop(problem, turn, taken):
    """A run that rejected nothing, fitting the median loop better than its start: the
    narrower run's stages (here ending at the least-squares solution) replace it where their
    median loop closure's s is more than ``OFF_BY`` times lower (a map crumpled to fit false
    loops within a width far wider than the noise), whatever the TLS objectives at the file's
    information; only then are their decisions settled and searched from."""
    graph, kernel, start, solved, _ = problem
    first = _turned(solved, turn)  # median s of the loops: 19x and 1.8x the solution's
    measured = kernel.measured[: graph.num_edges]
    assert not second_opinion.fits_median_worse(graph, measured, start, first.values)
    work, seen = graph.copy(), []
    edges = work.edges
    searched = dataclasses.replace(solved)
    opinion = _runs(work, kernel, start, solved, seen, searched).second_opinion(first)
    assert (opinion is not None) is taken
    assert (work.edges is edges) is not taken  # the narrower information kept where taken
    narrower = second_opinion.NARROWER * graph.edges.information
    information, values, search, after = seen[0]  # asked, its stages alone
    assert np.allclose(information, narrower, rtol=1e-12, atol=0)
    assert np.allclose(values.as_matrix(), start.as_matrix()) and not search and after is None
    assert len(seen) == (2 if taken else 1)  # searched only where taken
    if taken:
        information, values, search, after = seen[1]
        assert after is solved and opinion[0] is searched  # from the stages' decisions
        assert np.allclose(information, narrower, rtol=1e-12, atol=0)
        assert np.allclose(values.as_matrix(), solved.values.as_matrix())


def test_calibration_goes_on_from_a_second_opinion_taken(problem, monkeypatch):
    """``calibrate``'s check found no gross outlier; the second opinion taken, calibration
    counts its solve and its factor, and scales from its solution."""
    graph, _, _, solved, bent = problem
    kind = "loop closures"
    script = iter(
        [calibration.Estimate({kind: 1.0}, {kind: 1.0}, [], 0)]  # the check: nothing gross
        + [calibration.Estimate({kind: 4.0}, {kind: 4.0}, [], 0)] * 2
    )
    monkeypatch.setattr(calibration, "estimate", lambda *args, **kwargs: next(script))
    asked, solved_again = [], []

    def second(first):
        asked.append(first)
        return solved, 100.0

    def solve(last):
        assert last is solved  # settles the decisions of the second opinion's solve
        solved_again.append(solved)
        return solved

    result, found, _ = calibration.calibrate(
        graph.copy(), bent, solve, automatic=True, robust=True, covered=(kind,), second=second
    )
    assert asked == [bent]
    assert len(solved_again) == 1 and result is solved
    assert found.automatic is True and found.solves == 2 and found.second_opinion is True
    assert found.scales[kind] == pytest.approx(400.0) and "priors" not in found.scales


def test_gnc_anew_replaces_a_settled_solution_only_where_its_objective_is_lower(problem):
    graph, kernel, start, solved, bent = problem
    work, seen = graph.copy(), []
    assert _runs(work, kernel, start, solved, seen).anew(bent) is solved
    ((information, values, searched, _),) = seen
    assert np.array_equal(information, graph.edges.information)  # at the graph's information
    assert np.allclose(values.as_matrix(), start.as_matrix())  # from the start
    assert searched  # with its local search unless asked
    assert _runs(work, kernel, start, bent, seen).anew(solved) is None
    assert _runs(work, kernel, start, solved, seen).anew(bent, search=False) is solved
    assert seen[-1][2] is False


@pytest.mark.parametrize("lower", [True, False])
def test_calibration_runs_gnc_anew_where_consistent_rejections_set_it_off(
    problem, monkeypatch, lower
):
    """``calibrate``'s check found rejections that the kept measurements' noise explains;
    once the scaling settles, GNC runs anew, and its result is taken where ``anew`` gives one
    (its TLS objective was lower), counted as a solve."""
    graph, _, _, solved, bent = problem
    kind = "loop closures"
    script = iter(
        [calibration.Estimate({kind: 0.1}, {kind: 0.1}, [], 0, consistent=5)]
        + [calibration.Estimate({kind: 1.0}, {kind: 1.0}, [], 0)] * 2
    )
    monkeypatch.setattr(calibration, "estimate", lambda *args, **kwargs: next(script))
    asked = []

    def anew(settled, search=True):
        assert search  # once settled, GNC anew searches locally
        asked.append(settled)
        return solved if lower else None

    result, found, _ = calibration.calibrate(
        graph.copy(), bent, lambda last: bent, True, True, (kind,), anew=anew
    )
    assert asked == [bent]
    assert result is (solved if lower else bent)
    assert found.solves == (2 if lower else 1) and found.consistent_rejections == 5
    assert found.scales[kind] == pytest.approx(0.1)


@pytest.mark.parametrize("lower", [True, False])
def test_a_narrowing_scaling_runs_gnc_anew_and_searches_once_the_width_holds(
    problem, monkeypatch, lower
):
    """``calibrate``'s check found gross outliers kept under a width 4× too wide: GNC runs anew
    at the narrower width without its local search, and where its result is taken (its TLS
    objective was lower), the next solve settles its decisions and searches from them once
    the scales hold; where it is not, the decisions of the first run are settled instead."""
    graph, _, _, solved, bent = problem
    kind = "loop closures"
    script = iter(
        [calibration.Estimate({kind: 4.0}, {kind: 4.0}, [], 3)]
        + [calibration.Estimate({kind: 1.0}, {kind: 1.0}, [], 0)] * 2
    )
    monkeypatch.setattr(calibration, "estimate", lambda *args, **kwargs: next(script))
    asked, settled_from = [], []
    searched = _turned(solved, 0.001)

    def anew(last, search=True):
        asked.append((last, search))
        return solved if lower else None

    def solve(last):
        settled_from.append(last)
        return searched

    result, found, _ = calibration.calibrate(
        graph.copy(), bent, solve, True, True, (kind,), anew=anew
    )
    assert asked == [(bent, False)]
    assert settled_from == [solved if lower else bent] and result is searched
    assert found.solves == (2 if lower else 1)
    assert found.scales[kind] == pytest.approx(4.0)
