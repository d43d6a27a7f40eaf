"""The fixed-lag Smoother: its window's minimum, its marginalisation (against the batch solution
of the whole graph, which marginalisation reproduces where the problem is linear), the
estimates it keeps, and what it refuses."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import visual_odometry

import posegraph
from posegraph import PoseGraph, Smoother, SolverOptions, optimize
from posegraph.lie import SE2, SE3
from posegraph.smoother.marginal import marginalized, quadratic
from posegraph.solvers import GRADIENT_BELOW_TOLERANCE

TIGHT = SolverOptions(relative_decrease=1e-14)


def streamed(full: PoseGraph, lag: int | None = None, each=None, stamps=None) -> PoseGraph:
    """Stream ``full`` one pose per call (with its edges and priors) into a fixed-lag Smoother,
    new poses without values; ``each(k, graph, smoother)`` after every call. With ``stamps``
    (seconds per pose), the lag is 0.45 s. Returns the smoother's graph."""
    graph = PoseGraph(full.group)
    smoother = Smoother(graph, lag=lag, lag_seconds=None if stamps is None else 0.45)
    ends = np.maximum(full.edges.i, full.edges.j)
    for k in range(full.num_nodes):
        graph.add_node(k, full.values[0] if k == 0 else None)
        if stamps is not None:
            smoother.timestamps[k] = stamps[k]
        on = full.priors.i == k
        graph.add_priors(
            full.priors.i[on], full.priors.measurements[on], full.priors.information[on]
        )
        e = np.flatnonzero(ends == k)
        graph.add_edges(
            full.edges.i[e], full.edges.j[e], full.edges.measurements[e], full.edges.information[e]
        )
        smoother.optimize(options=TIGHT)
        if each is not None:
            each(k, graph, smoother)
    return graph


def batch(full: PoseGraph) -> PoseGraph:
    graph = full.copy()
    optimize(graph, init="file", options=SolverOptions(relative_decrease=1e-15))
    return graph


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_a_lag_longer_than_the_stream_reaches_the_batch_optimum(group):
    full, _ = visual_odometry(group, poses=30, seed=2)
    ours, reference = streamed(full, lag=100), batch(full)
    assert np.abs(ours.values.as_matrix() - reference.values.as_matrix()).max() < 1e-7


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_marginalisation_is_exact_where_the_problem_is_linear(group):
    """With noise of 1e-5 the measurements are nearly linear in the poses; the newest pose of
    each call then equals the batch solution of everything streamed so far, although only five
    poses are optimised: the prior holds what the marginalised ones knew. To 1e-6 m over tens
    of metres: H's pivots span 1e3 to 1e11, so the batch's own solution is determined to about
    1e-7 m (LLᵀ and LDLᵀ factorisations end that far apart, at the same error to 1e-11)."""
    full, _ = visual_odometry(
        group, poses=40, reach=5, translation_sigma=1e-5, rotation_sigma=1e-5, seed=4
    )
    newest = []
    streamed(full, lag=5, each=lambda k, graph, _: newest.append(graph.values[k].as_matrix()))
    for k in (10, 25, 39):
        prefix = full.copy()
        prefix.remove_nodes(np.arange(k + 1, full.num_nodes))
        reference = batch(prefix).values[k].as_matrix()
        assert np.abs(newest[k] - reference).max() < 1e-6


def test_marginalised_poses_keep_their_last_estimate():
    full, _ = visual_odometry(SE2, poses=25, seed=5)
    history = []
    final = streamed(full, lag=6, each=lambda k, graph, _: history.append(graph.values.as_matrix()))
    for k in range(full.num_nodes - 6):
        last = history[k + 6][k]  # the call that marginalised pose k
        assert np.array_equal(final.values[k].as_matrix(), last)


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_a_window_that_fits_exactly_tries_no_step(group):
    """A prior and a chain of odometry, the new pose composed from the last: the window fits
    every measurement to round-off, so the model's gradient is below ``gradient_tolerance``
    and no λ is tried (each would fail on round-off)."""
    full, _ = visual_odometry(group, poses=8, loop_share=0.0, seed=3)
    summaries = []
    streamed(full, lag=4, each=lambda k, graph, smoother: summaries.append(smoother.solution))
    for solution in summaries[2:]:
        summary = solution.summary
        assert summary.final_error < 1e-20
        assert summary.iterations == [] and summary.converged
        assert summary.termination == GRADIENT_BELOW_TOLERANCE


def test_the_schur_complement_keeps_the_marginal_of_the_kept_nodes():
    full, _ = visual_odometry(SE3, poses=6, seed=6)
    model = quadratic(full.values, full.edges, full.priors, np.arange(6))
    kept = np.array([False, False, True, True, False, True])
    hessian, gradient, constant = marginalized(model, kept, 6)
    entries = np.repeat(kept, 6)
    covariance = np.linalg.inv(model.hessian)
    assert np.allclose(np.linalg.inv(hessian), covariance[np.ix_(entries, entries)], rtol=1e-9)
    minimiser = np.linalg.solve(model.hessian, model.gradient)
    assert np.allclose(np.linalg.solve(hessian, gradient), minimiser[entries], atol=1e-12)
    full_minimum = model.constant - 0.5 * model.gradient @ minimiser
    kept_minimum = constant - 0.5 * gradient @ np.linalg.solve(hessian, gradient)
    assert kept_minimum == pytest.approx(full_minimum, rel=1e-9, abs=1e-12)


def test_a_measurement_on_a_marginalised_pose_is_refused():
    graph = PoseGraph(SE2)
    smoother = Smoother(graph, lag=4)
    graph.add_node(0, SE2.identity())
    graph.add_prior(0, SE2.identity(), np.eye(3))
    for k in range(1, 8):
        graph.add_node(k)
        graph.add_edge(k - 1, k, SE2.from_xytheta([1.0, 0.0, 0.1]), np.eye(3))
        smoother.optimize()
    graph.add_edge(1, 7, SE2.from_xytheta([6.0, 0.0, 0.6]), np.eye(3))
    with pytest.raises(ValueError, match="node 1, which left the fixed-lag window of 4 poses"):
        smoother.optimize()


def test_what_a_fixed_lag_smoother_refuses():
    graph = PoseGraph(SE2)
    graph.add_node(0, SE2.identity())
    graph.add_node(1, SE2.identity())
    graph.add_edge(0, 1, SE2.identity(), np.eye(3))
    smoother = Smoother(graph, lag=2)
    with pytest.raises(ValueError, match="robust, init and calibrate_noise"):
        smoother.optimize(robust="gnc")
    with pytest.raises(ValueError, match="only grows"):
        smoother.remove_edges([0])
    with pytest.raises(ValueError, match="number of newest poses"):
        Smoother(graph, lag=0)
    with pytest.raises(ValueError, match="in poses .* or in seconds, not both"):
        Smoother(graph, lag=3, lag_seconds=1.0)
    with pytest.raises(ValueError, match="covariances of a fixed-lag Smoother's window"):
        posegraph.marginals(smoother, [1])
    with pytest.raises(ValueError, match="timestamps belong to a Smoother made with lag_seconds"):
        _ = smoother.timestamps


def test_a_lag_in_seconds_keeps_the_poses_stamped_within_it():
    full, _ = visual_odometry(SE2, poses=40, reach=4, seed=8)
    rng = np.random.default_rng(8)
    for stamps, same_as_poses in (
        (0.1 * np.arange(40), True),  # 0.45 s keep the newest five poses, as lag=5
        (np.cumsum(rng.uniform(0.05, 0.15, 40)), False),
    ):
        windows: list[np.ndarray] = []

        def record(k, graph, smoother, windows=windows):
            windows.append(np.flatnonzero(~smoother.fixed_lag.marginalized))

        graph = streamed(full, stamps=stamps, each=record)
        for k, window in enumerate(windows):
            assert np.array_equal(window, np.flatnonzero(stamps[: k + 1] >= stamps[k] - 0.45))
        if same_as_poses:
            assert np.allclose(
                graph.values.as_matrix(), streamed(full, lag=5).values.as_matrix(), atol=1e-12
            )
    smoother = Smoother(graph, lag_seconds=1.0)
    with pytest.raises(ValueError, match="node 0 has no timestamp"):
        smoother.optimize()
