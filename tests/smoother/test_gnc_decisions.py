"""GNC's decisions carried by the smoother: when they stand, when GNC decides again, and what the
rejections leave."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.benchmarks.incremental import arrivals, run, stream
from posegraph.graph import PoseGraph, odometry_mask
from posegraph.io import read_graph, write_graph
from posegraph.lie import SE2
from posegraph.robust.spec import gnc_quantile, robust_mask
from posegraph.smoother import COMPOSED
from posegraph.solvers import STOPPED
from tests.smoother.helpers import drive_on, searched_from_decisions

from ..conftest import city_with_fixes, cull


def _city_with_false_loops() -> tuple[PoseGraph, np.ndarray]:
    graph, _ = manhattan_world(num_poses=150, seed=93)
    return add_false_loops(graph, 0.1, seed=1)


def _stages(summary) -> set[str]:
    return {record.stage for record in summary.iterations}


def _add_loop(smoother: posegraph.Smoother) -> None:
    graph = smoother.graph
    graph.add_edge(3, 140, SE2.from_xytheta([5.0, 0.0, 0.0]), np.eye(3) * 100.0)


def _add_second_odometry(smoother: posegraph.Smoother) -> None:
    graph = smoother.graph
    graph.add_edge(10, 11, graph.edges.measurements[10], graph.edges.information[10])


def _add_prior(smoother: posegraph.Smoother) -> None:
    graph = smoother.graph
    graph.add_prior(151, SE2.from_xytheta([0.0, 0.0, 0.0]), np.eye(3))


def _one_true_loop_trusted(graph: PoseGraph) -> np.ndarray:
    mask = robust_mask(graph, "loops")
    mask[np.flatnonzero(mask)[0]] = False
    return mask


def _remove_first_loop(smoother: posegraph.Smoother) -> None:
    smoother.remove_edges([np.flatnonzero(robust_mask(smoother.graph, "loops"))[0]])


def _remeasure_first_loop(smoother: posegraph.Smoother) -> None:
    graph = smoother.graph
    """Replaces the first loop's measurement in place by one a little off, as a caller may."""
    first = np.flatnonzero(robust_mask(graph, "loops"))[0]
    nudged = graph.edges.measurements[first] @ SE2.from_xytheta([0.01, 0.0, 0.0])
    moved = graph.edges.measurements.set_at([first], nudged)
    graph.edges = dataclasses.replace(graph.edges, measurements=moved)


def _replace_first_prior(smoother: posegraph.Smoother) -> None:
    graph = smoother.graph
    """Replaces the prior added before the first solve in place, as a caller may."""
    moved = graph.priors.measurements.set_at([0], SE2.from_xytheta([0.1, 0.0, 0.0]))
    graph.priors = dataclasses.replace(graph.priors, measurements=moved)


def test_streaming_with_false_loops_rejects_them_as_a_batch_call_does(tmp_path):
    """The incremental benchmark's robust mode (``--robust gnc --false-loops``): every call of
    the stream, warm-started, runs GNC, and the last one rejects exactly the false loops, which
    the benchmark finds among the streamed edges (they arrive in another order than the file's),
    as a call from scratch on the whole graph does."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    path = tmp_path / "manhattan.g2o"
    write_graph(graph, str(path))
    report = run(path, 50, robust="gnc", false_loops=0.1, seed=1)
    exactly_the_false_loops = "100.0% of the false loops and 0.00% of the true ones"
    assert f"reject {exactly_the_false_loops} (warm), {exactly_the_false_loops} (scratch)" in report
    assert "(3 optimisations)" in report


def test_gnc_decisions_stand_when_only_trusted_odometry_was_added():
    """New poses that hang off the map by odometry alone leave the TLS problem over the solved
    poses as it was: the call keeps GNC's decisions and composes the new poses, and ends where
    GNC run again on the grown graph ends. Where the solved poses moved since, it solves over
    the decisions in least squares instead."""
    graph, false = _city_with_false_loops()
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize(robust="gnc")
    assert first.summary.rejected_edges == np.flatnonzero(false).tolist()
    drive_on(graph, 5)
    grown = graph.copy()
    second = smoother.optimize(robust="gnc")
    assert second.summary.rejected_edges == first.summary.rejected_edges
    assert f"GNC's decisions ({false.sum()} rejected" in ", ".join(second.summary.reused)
    assert second.summary.termination == COMPOSED and second.summary.num_iterations == 0
    assert second.summary.robust == first.summary.robust
    assert second.summary.edges_under_kernel == first.summary.edges_under_kernel
    assert second.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-9)
    assert graph.values[:150].same_as(first.values)
    again = posegraph.optimize(grown, robust="gnc")
    assert "least squares" in _stages(again.summary)
    assert again.summary.rejected_edges == second.summary.rejected_edges
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-6)
    graph.set_values(graph.values.retract(np.full((graph.num_nodes, 3), 1e-3)))
    drive_on(graph, 5)
    third = smoother.optimize(robust="gnc")
    assert _stages(third.summary) == {"carried decisions"} and third.summary.converged
    assert third.summary.rejected_edges == first.summary.rejected_edges


def test_gnc_decisions_on_loops_and_priors_stand_when_only_odometry_was_added():
    """With ``robust_priors`` the robust problem holds the priors too, as edges after the
    between edges: the carried decisions keep the rejected fixes out as well."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    graph, false_loops = add_false_loops(graph, 0.1, seed=2)
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize(robust="gnc", robust_priors=True)
    assert first.summary.rejected_priors == np.flatnonzero(false_fixes).tolist()
    assert first.summary.rejected_edges == np.flatnonzero(false_loops).tolist()
    drive_on(graph, 5)
    grown = graph.copy()
    second = smoother.optimize(robust="gnc", robust_priors=True)
    again = posegraph.optimize(grown, robust="gnc", robust_priors=True)
    assert second.summary.termination == COMPOSED
    assert "least squares" in _stages(again.summary)
    assert second.summary.rejected_priors == again.summary.rejected_priors
    assert second.summary.rejected_edges == again.summary.rejected_edges
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-6)
    np.testing.assert_array_equal(smoother.solution.prior_weights, (~false_fixes).astype(float))


def test_gnc_decisions_stand_for_the_same_edge_class_given_as_indices_then_as_a_mask():
    """The robust class is compared edge by edge, however the caller gave it: loop closures
    given as indices, then (after new odometry) as a mask that leaves the new edges out."""
    graph, false = _city_with_false_loops()
    loops = robust_mask(graph, "loops")
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize(robust="gnc", robust_edges=np.flatnonzero(loops))
    assert first.summary.rejected_edges == np.flatnonzero(false).tolist()
    drive_on(graph, 5)
    mask = np.append(loops, np.zeros(5, dtype=bool))
    second = smoother.optimize(robust="gnc", robust_edges=mask)
    assert _stages(second.summary) <= {"carried decisions"}
    assert second.summary.rejected_edges == first.summary.rejected_edges


@pytest.mark.parametrize(
    "change, robust, robust_edges, search",
    [
        (_add_loop, "gnc", "loops", "both"),
        (_add_second_odometry, "gnc", "loops", "decisions"),
        (_add_prior, "gnc", "loops", "decisions"),
        (lambda smoother: smoother.graph.fix([151]), "gnc", "loops", "decisions"),
        (lambda smoother: None, "gnc:3", "loops", "stages"),
        (lambda smoother: None, "gnc", _one_true_loop_trusted, "stages"),
        (_remove_first_loop, "gnc", "loops", "decisions"),
        (_replace_first_prior, "gnc", "loops", "stages"),
        (_remeasure_first_loop, "gnc", "loops", "stages"),
    ],
    ids=[
        "a new false loop",
        "a cycle of trusted edges",
        "a prior",
        "a hold",
        "another width",
        "one old edge left out of the class",
        "an old loop removed",
        "a prior replaced",
        "an old loop remeasured",
    ],
)
def test_gnc_decides_again_when_what_was_added_could_change_its_decisions(
    change, robust, robust_edges, search
):
    """The decisions do not stand, and the call searches: from them alone where the graph only
    grew (or lost an old loop: ``Smoother.remove_edges`` carries them) under the same kernel
    and least squares over them settles as it is; from GNC's stages where they are not carried;
    from the better of both where least squares over them does not settle as it is (the new
    false loop, which they keep, misfits there). Either way the new false loop ends rejected."""
    graph, _ = _city_with_false_loops()
    graph.add_prior(0, SE2.identity(), np.eye(3))
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize(robust="gnc")
    drive_on(graph, 5)
    change(smoother)
    if callable(robust_edges):
        robust_edges = robust_edges(graph)
    summary = smoother.optimize(robust=robust, robust_edges=robust_edges).summary
    assert not any("nothing added since" in reuse for reuse in summary.reused)
    assert summary.termination != COMPOSED
    assert ("least squares" in _stages(summary)) == (search != "decisions")
    if search == "decisions":
        assert searched_from_decisions(summary)
    if search == "stages":
        assert not searched_from_decisions(summary) and "previous decisions" not in _stages(summary)
    if search == "both":
        assert {"previous decisions", "least squares"} <= _stages(summary)
        assert summary.rejected_edges == [*first.summary.rejected_edges, graph.num_edges - 1]


def test_gnc_searches_from_its_decisions_when_a_true_loop_arrives():
    """A true loop closed after the last GNC run: least squares over the run's decisions with
    the loop kept settles as it is, so the search starts there, and ends where GNC on the whole
    graph from scratch ends."""
    graph, false = _city_with_false_loops()
    true_loops = np.flatnonzero(robust_mask(graph, "loops") & ~false)
    held_out = graph.edges.subset([true_loops[-1]])
    ends = graph.node_ids[held_out.i[0]], graph.node_ids[held_out.j[0]]
    graph.remove_edges([true_loops[-1]])
    false = np.append(np.delete(false, true_loops[-1]), False)
    smoother = posegraph.Smoother(graph)
    first = smoother.optimize(robust="gnc")
    graph.add_edge(*ends, held_out.measurements[0], held_out.information[0])
    scratch = graph.copy()
    second = smoother.optimize(robust="gnc")
    assert searched_from_decisions(second.summary)
    assert "least squares" not in _stages(second.summary)
    assert "previous decisions" in _stages(second.summary)
    assert second.summary.rejected_edges == np.flatnonzero(false).tolist()
    assert np.abs(first.values.between(second.values).log()).max() > 1e-3  # the loop moved it
    again = posegraph.optimize(scratch, robust="gnc")
    assert again.summary.rejected_edges == second.summary.rejected_edges
    assert second.summary.final_error == pytest.approx(again.summary.final_error, rel=1e-9)
    # Both stop at Levenberg-Marquardt's tolerance, from different starts (poses ≈ 10 apart).
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-5)


def test_gnc_streamed_keeps_decisions_that_beat_its_stages(shared_dataset):
    """MIT with 30% false loops (seed 0), streamed in steps of 10 poses, GNC at every step. At
    the step to 800 poses, least squares over the last decisions with the new loops misfits, and
    GNC's stages from there keep a false loop and reject three true ones; the decisions settled
    from that solution reach a lower TLS objective, and the search goes on from them. The stream
    ends with every false loop rejected and every true one kept, below the TLS objective of GNC
    on the whole graph from scratch at the file's information (which rejects 2 of the 20 true
    loops; robust mode would then calibrate)."""
    full = read_graph(shared_dataset("MIT.g2o")).graph
    full, false = add_false_loops(full, 0.3, seed=0)
    false = false[np.argsort(arrivals(full, 10)[1], kind="stable")]
    smoother = None
    for graph in stream(full, 10):
        smoother = smoother or posegraph.Smoother(graph)
        summary = smoother.optimize(robust="gnc").summary
    assert summary.rejected_edges == np.flatnonzero(false).tolist()
    scratch = graph.copy()
    from_scratch = posegraph.optimize(scratch, robust="gnc", calibrate_noise=False).summary
    assert summary.final_error < from_scratch.final_error


@pytest.mark.parametrize("which", ["true", "false"])
def test_gnc_with_robust_priors_searches_on_when_a_fix_arrives(which):
    """With ``robust_priors`` a new fix (a prior) is a new measurement under the kernel: the
    call searches, from the last run's decisions where least squares over them settles, and
    ends with the rejections of GNC on the whole graph from scratch."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    last = np.flatnonzero(false_fixes == (which == "false"))[-1]
    held_out = graph.priors.subset([last])
    kept = np.arange(len(graph.priors)) != last
    graph.priors = graph.priors.subset(kept)
    smoother = posegraph.Smoother(graph)
    smoother.optimize(robust="gnc", robust_priors=True)
    graph.add_prior(
        graph.node_ids[held_out.i[0]], held_out.measurements[0], held_out.information[0]
    )
    scratch = graph.copy()
    second = smoother.optimize(robust="gnc", robust_priors=True).summary
    again = posegraph.optimize(scratch, robust="gnc", robust_priors=True).summary
    false_now = np.append(false_fixes[kept], which == "false")
    assert second.rejected_priors == again.rejected_priors == np.flatnonzero(false_now).tolist()
    if which == "true":
        assert searched_from_decisions(second) and "least squares" not in _stages(second)


def test_gnc_decides_again_when_the_priors_leave_the_kernel():
    graph, _ = city_with_fixes(0.3, seed=0)
    smoother = posegraph.Smoother(graph)
    smoother.optimize(robust="gnc", robust_priors=True)
    drive_on(graph, 5)
    summary = smoother.optimize(robust="gnc").summary
    assert "least squares" in _stages(summary) and not summary.rejected_priors


def test_gnc_decides_again_after_a_run_that_was_stopped():
    graph, _ = _city_with_false_loops()
    smoother = posegraph.Smoother(graph)
    stopped = smoother.optimize(robust="gnc", callback=lambda record: True)
    assert stopped.summary.termination == STOPPED
    summary = smoother.optimize(robust="gnc").summary
    assert "least squares" in _stages(summary) and "carried decisions" not in _stages(summary)


def test_gnc_with_fixes_searches_from_its_decisions_after_a_fix_and_a_keyframe_go():
    """Under ``robust_priors`` the GNC problem holds the edges, then the priors: removing a
    false fix and culling a keyframe with a fix keeps the decisions on what remains, and the
    search from them rejects what GNC from scratch rejects."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    smoother = posegraph.Smoother(corrupted)
    smoother.optimize(robust="gnc", robust_priors=True)
    smoother.remove_priors([np.flatnonzero(false_fixes)[0]])
    fixed_nodes = corrupted.node_ids[corrupted.priors.i]
    cull(smoother, int(fixed_nodes[(fixed_nodes > 0) & (fixed_nodes < 299)][3]))
    edges, priors = smoother.rejected()
    assert edges.sum() == false_loops.sum() and priors.sum() == false_fixes.sum() - 1
    scratch = corrupted.copy()
    warm = smoother.optimize(robust="gnc", robust_priors=True).summary
    fresh = posegraph.optimize(scratch, robust="gnc", robust_priors=True).summary
    assert searched_from_decisions(warm) and not searched_from_decisions(fresh)
    assert warm.rejected_edges == fresh.rejected_edges == np.flatnonzero(edges).tolist()
    assert warm.rejected_priors == fresh.rejected_priors == np.flatnonzero(priors).tolist()
    assert warm.final_error == pytest.approx(fresh.final_error, rel=1e-6)


def test_without_rejected_keeps_what_a_robust_solve_kept():
    """After GNC, ``rejected`` marks exactly the false loops and the false fixes, and
    ``without_rejected`` holds the rest. GNC's last solve is least squares over its decisions,
    so least squares over the inliers stays at the robust solution, where the TLS cost is theirs
    plus ½c² for each rejected measurement (c = √χ²₃(0.999)). Measurements added since are not
    rejected; those that remain after a removal keep theirs (``Solution.without``), and a
    measurement changed in place makes its kind's rejections unknown."""
    from scipy.stats import chi2 as chi2_distribution

    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    smoother = posegraph.Smoother(corrupted)
    robust = smoother.optimize(robust="gnc", robust_priors=True)
    edges, priors = smoother.rejected()
    np.testing.assert_array_equal(edges, false_loops)
    np.testing.assert_array_equal(priors, false_fixes)
    inliers = smoother.without_rejected()
    np.testing.assert_array_equal(inliers.edges.i, corrupted.edges.i[~false_loops])
    np.testing.assert_array_equal(inliers.edges.j, corrupted.edges.j[~false_loops])
    np.testing.assert_array_equal(inliers.priors.i, corrupted.priors.i[~false_fixes])
    of_inliers = posegraph.Smoother(inliers)
    assert not of_inliers.rejected()[0].any() and not of_inliers.rejected()[1].any()
    least_squares = of_inliers.optimize(init="file")
    assert least_squares.summary.final_error == pytest.approx(
        least_squares.summary.initial_error, rel=1e-9
    )
    np.testing.assert_allclose(inliers.positions(), corrupted.positions(), atol=1e-6)
    under_kernel = (~odometry_mask(corrupted)).sum() + len(corrupted.priors)
    width_squared = chi2_distribution.ppf(gnc_quantile(int(under_kernel)), 3)
    rejected = false_loops.sum() + false_fixes.sum()
    assert robust.summary.final_error == pytest.approx(
        least_squares.summary.final_error + 0.5 * width_squared * rejected, rel=1e-9
    )
    corrupted.add_edge(0, 299, graph.values[0].between(graph.values[299]), np.eye(3))
    edges, priors = smoother.rejected()
    np.testing.assert_array_equal(edges, np.append(false_loops, False))
    np.testing.assert_array_equal(priors, false_fixes)
    smoother.remove_edges([0])
    smoother.remove_priors([np.flatnonzero(false_fixes)[0]])
    edges, priors = smoother.rejected()
    np.testing.assert_array_equal(edges, np.append(false_loops, False)[1:])
    np.testing.assert_array_equal(priors, np.delete(false_fixes, np.flatnonzero(false_fixes)[0]))
    assert edges.any() and priors.any()
    moved = corrupted.priors.measurements.retract(np.full((len(corrupted.priors), 3), 0.1))
    corrupted.priors = dataclasses.replace(corrupted.priors, measurements=moved)
    edges, priors = smoother.rejected()
    assert edges.any() and not priors.any()
    least_squares = posegraph.Smoother(graph)
    least_squares.optimize()
    assert not any(mask.any() for mask in least_squares.rejected())  # it rejects nothing
