"""Noise calibration: it restores information scaled away from the simulated noise, and robust
mode calibrates where that scaling hid false loops, and only there."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops, rejection_rates

import posegraph
from posegraph.graph import odometry_mask
from posegraph.problem.factors import chi2
from posegraph.robust import calibration, noise
from posegraph.robust.gnc import gnc_tls
from posegraph.robust.kernels import default_width
from posegraph.robust.run import DECISIONS_AS_START


@pytest.fixture(scope="module")
def simulated():
    """A manhattan world whose measurements' noise is what their information states, and its
    least-squares solution."""
    graph, _ = manhattan_world(1000, seed=3)
    return graph, posegraph.optimize(graph.copy()).values


def _scaled(graph: posegraph.PoseGraph, odometry: float, loops: float) -> posegraph.PoseGraph:
    weights = np.where(odometry_mask(graph), odometry, loops)
    return graph.weighted(weights)


def _distance(a, b) -> float:
    return float(np.abs(a.translation - b.translation).max())


def test_calibration_restores_each_class_s_information(simulated):
    """Odometry stated 100× too noisy and loops 100× too precise: the scales undo both, and
    the solution is the one of the true information, where least squares on the scaled
    information is not."""
    graph, solution = simulated
    scaled = _scaled(graph, 1e-2, 1e2)
    uncalibrated = posegraph.optimize(scaled.copy()).values
    work = scaled.copy()
    result = posegraph.optimize(work, calibrate_noise=True)
    scales = result.summary.calibration["scales"]
    assert result.summary.calibration["automatic"] is False
    assert 70 < scales["odometry"] < 130
    assert 0.007 < scales["loop closures"] < 0.013
    assert _distance(result.values, solution) < 0.1 * _distance(uncalibrated, solution)
    # The graph holds the scaled information, and the noise check is 1 per degree of freedom.
    factor = work.edges.information[0, 0, 0] / scaled.edges.information[0, 0, 0]
    assert factor == pytest.approx(scales["odometry"], rel=1e-9)
    for noise_class in result.summary.noise:
        assert noise_class["chi2_per_dof"] == pytest.approx(1.0, abs=0.3)


def test_robust_mode_calibrates_where_the_information_hides_false_loops(simulated):
    """With the information stating 100× the noise, GNC's default width keeps false loops;
    robust mode finds that, scales the information, and rejects them. After each scaling that
    narrows the width, GNC graduates anew without its local search; once the width holds, the
    last solve settles its decisions and searches from them without graduating."""
    graph, _ = simulated
    corrupted, false = add_false_loops(_scaled(graph, 1e-2, 1e-2), 0.3, seed=0)
    left = posegraph.optimize(corrupted.copy(), robust="gnc", calibrate_noise=False)
    rejected_false, _ = rejection_rates(corrupted, false, np.array(left.summary.rejected_edges))
    assert rejected_false < 0.99  # what calibration is for
    result = posegraph.optimize(corrupted.copy(), robust="gnc")
    rejected_false, rejected_true = rejection_rates(
        corrupted, false, np.array(result.summary.rejected_edges)
    )
    assert rejected_false == 1.0 and rejected_true <= 0.001
    calibration = result.summary.calibration
    assert calibration["automatic"] is True
    assert all(50 < scale < 200 for scale in calibration["scales"].values())
    assert calibration["solves"] == 3
    stages = [stage for stage, _ in itertools.groupby(r.stage for r in result.summary.iterations)]
    graduations = [i for i, stage in enumerate(stages) if stage == "gnc round 1 (chordal)"]
    assert len(graduations) == 3  # the first run's and two after a scaling
    # The last solve starts from decisions of this call, not from an earlier call's.
    assert not any(DECISIONS_AS_START in reuse for reuse in result.summary.reused)
    searched = {"re-admit", "drop"}
    assert searched & set(stages[: graduations[1]])  # the first run searched
    assert not searched & set(stages[graduations[1] : graduations[2]])  # the next did not


def test_robust_mode_calibrates_where_its_width_rejects_true_loops():
    """With the information stating a hundredth of the noise, GNC's default width rejects
    nearly every true loop with the false ones. The odometry it keeps shows the noise, and
    under that noise most of the rejected loops pass the test: robust mode scales every class
    by it and takes them back, the false loops still out."""
    graph, _ = manhattan_world(300, seed=3)
    corrupted, false = add_false_loops(_scaled(graph, 1e2, 1e2), 0.3, seed=0)
    left = posegraph.optimize(corrupted.copy(), robust="gnc", calibrate_noise=False)
    _, rejected_true = rejection_rates(corrupted, false, np.array(left.summary.rejected_edges))
    assert rejected_true > 0.5  # what calibration is for
    result = posegraph.optimize(corrupted.copy(), robust="gnc")
    rejected_false, rejected_true = rejection_rates(
        corrupted, false, np.array(result.summary.rejected_edges)
    )
    assert rejected_false == 1.0 and rejected_true <= 0.01
    calibration = result.summary.calibration
    assert calibration["automatic"] is True and calibration["consistent_rejections"] > 10
    assert calibration["scales"].keys() == {"odometry", "loop closures"}
    assert all(0.005 < scale < 0.02 for scale in calibration["scales"].values())


def test_robust_mode_does_not_take_back_loops_that_are_all_false():
    """Every loop false, the information right: GNC rejects them all, and robust mode does not
    take the majority of what it rejected as true, as an asked-for calibration would."""
    graph, _ = manhattan_world(300, seed=3)
    loops = ~odometry_mask(graph)
    rng = np.random.default_rng(0)
    measurements = graph.edges.measurements.as_matrix()
    measurements[loops] = type(graph.edges.measurements).sample(rng, (loops.sum(),)).as_matrix()
    measurements[loops, :2, 2] = rng.uniform(-20.0, 20.0, size=(loops.sum(), 2))
    corrupted = graph.copy()
    corrupted.edges = dataclasses.replace(
        corrupted.edges, measurements=posegraph.SE2.from_matrix(measurements)
    )
    result = posegraph.optimize(corrupted.copy(), robust="gnc")
    assert set(result.summary.rejected_edges) == set(np.flatnonzero(loops))
    assert result.summary.calibration is None
    asked = posegraph.optimize(corrupted.copy(), robust="gnc", calibrate_noise=True)
    assert len(asked.summary.rejected_edges) < loops.sum() / 2


def test_robust_mode_leaves_information_that_hides_nothing(simulated):
    graph, _ = simulated
    corrupted, false = add_false_loops(graph, 0.1, seed=1)
    work = corrupted.copy()
    result = posegraph.optimize(work, robust="gnc")
    assert result.summary.calibration is None
    assert np.array_equal(work.edges.information, corrupted.edges.information)
    assert [c["kind"] for c in result.summary.noise] == ["odometry", "loop closures"]
    for noise_class in result.summary.noise:
        assert noise_class["chi2_per_dof"] == pytest.approx(1.0, abs=0.15)


def test_calibration_ends_where_a_widening_brings_gross_outliers_back(monkeypatch):
    """The control flow of ``calibrate`` on parking-garage's pattern (estimates scripted): gross
    outliers kept, so the median scale narrows the width; none left, so the tail scale widens
    it; gross outliers back at the wider width. Calibration ends there, with the solve after
    the widening (the decisions before it, settled at the wider width): the median scale of the
    last estimate is never applied, so the two scales do not alternate."""
    graph, _ = manhattan_world(num_poses=30, seed=3)
    first = posegraph.optimize(graph.copy())

    def estimated(median: float, tail: float, gross: int) -> calibration.Estimate:
        kind = "loop closures"
        return calibration.Estimate({kind: median}, {kind: tail}, [], gross)

    script = iter(
        [
            estimated(100.0, 200.0, 5),
            estimated(1.0, 0.1, 0),
            estimated(8.0, 0.9, 3),
        ]
    )
    monkeypatch.setattr(calibration, "estimate", lambda *args, **kwargs: next(script))
    solved = []

    def solve(last):
        summary = dataclasses.replace(first.summary, rejected_edges=[len(solved)])
        solved.append(dataclasses.replace(first, summary=summary))
        return solved[-1]

    result, found, _ = calibration.calibrate(
        graph, first, solve, automatic=True, robust=True, covered=("loop closures",)
    )
    assert len(solved) == 2 and result is solved[-1]
    assert found.scales == dict.fromkeys(["odometry", "loop closures"], pytest.approx(10.0))
    assert found.solves == 2


def test_the_noise_check_borrows_the_local_searchs_leverages_and_agrees_with_its_own(
    monkeypatch,
):
    """GNC's result carries the leverages its local search computed at its solution over the
    kept edges; the noise check of that result tests every measurement (kept ones by their
    deleted residuals, rejected ones by their innovations) as it does with leverages of its
    own, without computing deleted residuals again."""
    graph, _ = manhattan_world(400, seed=5)
    corrupted, _ = add_false_loops(graph, 0.1, seed=1)
    mask = ~odometry_mask(corrupted)
    outcome = gnc_tls(corrupted, mask, default_width(3, 0.999))
    result = outcome.result
    assert result.leverage is not None
    edge_inliers = np.ones(corrupted.num_edges, dtype=bool)
    edge_inliers[outcome.rejected] = False
    prior_inliers = np.ones(len(corrupted.priors), dtype=bool)
    work = calibration._inliers(corrupted, edge_inliers, prior_inliers)

    def tests_after(solved):
        return calibration._with_left_out(
            corrupted, work, result.values, edge_inliers, prior_inliers, solved
        )

    own = tests_after(dataclasses.replace(result, leverage=None))
    computed = []
    monkeypatch.setattr(noise, "deleted_residuals", lambda *a, **k: computed.append(a))
    lent = tests_after(result)
    assert computed == []
    for field in dataclasses.fields(own):
        np.testing.assert_allclose(
            getattr(lent, field.name), getattr(own, field.name), rtol=1e-9, atol=1e-12
        )


def _loop_tests(ratios: np.ndarray) -> noise.MeasurementTests:
    """Tests of loop closures (rank 3) whose d² is ``ratios`` times their χ²₃(0.999) limit."""
    ranks = np.full(ratios.size, 3)
    limits = noise.limits(ranks)
    tested = ratios * limits
    kinds = np.ones(ratios.size, dtype=np.int64)
    return noise.MeasurementTests(kinds, tested, np.full(ratios.size, 3.0), tested, ranks, limits)


def test_a_heavy_tail_of_true_loops_parted_from_the_false_ones_widens_the_tail_scale():
    """parking-garage's pattern: the true loops' tests run on from the bulk past ``OFF_BY``
    times the limit to about 45×, the false ones start at 1,300×. After a robust solve that
    rejected both, the heavy tail is not gross: the tail scale lets all but 0.1% of the true
    loops pass, and every false loop still fails by more than ``OFF_BY``. Where the true
    loops' tests run on into the false ones', the heavy ones stay gross and fail."""
    rng = np.random.default_rng(0)
    limit = default_width(3, 0.999) ** 2
    bulk = rng.chisquare(3, size=2000) / limit
    false = np.geomspace(1300.0, 1e5, 200)
    for heavy, parted in [
        (np.geomspace(1.5, 45.0, 40), True),
        (np.geomspace(1.5, 900.0, 40), False),
    ]:
        ratios = np.concatenate([bulk, heavy, false])
        inliers = np.arange(ratios.size) < bulk.size
        tests = _loop_tests(ratios)
        scale = calibration._estimate(tests, inliers).scales()["loop closures"]
        failing = tests.tested * scale > tests.limits
        true_failing = np.count_nonzero(failing[: bulk.size + heavy.size])
        assert np.all(
            tests.tested[-false.size :] * scale > noise.OFF_BY * tests.limits[-false.size :]
        )
        if parted:
            assert true_failing <= 0.001 * (bulk.size + heavy.size) + 1
        else:
            assert true_failing >= np.count_nonzero(heavy > noise.OFF_BY) - 1


@pytest.mark.parametrize(
    ("beyond", "gross_from"),
    [
        (np.geomspace(3.5, 45.0, 25), 45.0),  # a tail, then a jump: gross beyond the tail
        (np.geomspace(3.5, 900.0, 25), noise.OFF_BY),  # no jump of GAP: the tail runs on
        (np.array([12.0, 15.0]), noise.OFF_BY),  # two near false loops, not a tail
        (np.geomspace(3.5, 150.0, 25), noise.OFF_BY),  # the jump starts beyond TAIL_MAX
        (np.geomspace(40.0, 60.0, 25), noise.OFF_BY),  # a cluster a jump away from the bulk
        (np.array([]), noise.OFF_BY),  # nothing beyond OFF_BY
    ],
)
@pytest.mark.parametrize("false", [np.geomspace(3000.0, 1e5, 50), np.array([])])
def test_the_tail_ends_at_a_jump_after_enough_measurements_below_tail_max(
    beyond, gross_from, false
):
    """With false measurements far beyond, or none (a tail that ends where the tests do)."""
    bulk = np.linspace(0.01, 3.0, 5000)
    ratios = np.concatenate([bulk, beyond, false])
    assert noise.tail_end(np.random.default_rng(1).permutation(ratios)) == pytest.approx(gross_from)


@pytest.mark.parametrize(
    ("false", "gross_from"), [(np.geomspace(3000.0, 1e5, 50), 45.0), ([], 10.0)]
)
def test_a_tail_of_more_than_false_share_ends_only_at_a_jump(false, gross_from):
    """A smooth tail past ``OFF_BY`` holding 4% of the tests: true where a jump parts it from
    false measurements beyond; where it runs on to the last test, gross (w10000's false loops
    under a narrow width run on so, to 83× their limit)."""
    ratios = np.concatenate([np.linspace(0.01, 3.0, 5000), np.geomspace(3.5, 45.0, 400), false])
    assert noise.tail_end(ratios) == pytest.approx(gross_from)


def test_robust_mode_keeps_parking_garages_heavy_tailed_true_loops(shared_dataset):
    """parking-garage states about 20,000× its noise, and its true loops' tests run on to
    about 45× their limit under the noise the residuals show. With 10% false loops
    (``add_false_loops``, seed 0), robust mode calibrates, rejects every false loop and keeps
    every true one: its solution's error over the true measurements is the outlier-free
    optimum's within 1e-6."""
    graph = posegraph.read_graph(str(shared_dataset("parking-garage.g2o"))).graph
    optimum = posegraph.optimize(graph.copy())
    corrupted, false = add_false_loops(graph, 0.1, seed=0)
    result = posegraph.optimize(corrupted.copy(), robust="gnc")
    rejected_false, rejected_true = rejection_rates(
        corrupted, false, np.array(result.summary.rejected_edges)
    )
    assert rejected_false == 1.0 and rejected_true == 0.0
    assert result.summary.calibration["automatic"] is True
    error = 0.5 * chi2(result.values, graph.edges, graph.priors)
    assert error == pytest.approx(optimum.summary.final_error, rel=1e-6)


def test_robust_mode_keeps_parking_garages_true_loops_without_false_ones(shared_dataset):
    """On parking-garage as it is, whose true loops' tests run on to about 40× their limit
    and end there, robust mode rejects nothing, has nothing to calibrate, and ends at the
    least-squares optimum."""
    graph = posegraph.read_graph(str(shared_dataset("parking-garage.g2o"))).graph
    optimum = posegraph.optimize(graph.copy())
    result = posegraph.optimize(graph.copy(), robust="gnc")
    assert result.summary.rejected_edges == [] and result.summary.calibration is None
    error = 0.5 * chi2(result.values, graph.edges, graph.priors)
    assert error == pytest.approx(optimum.summary.final_error, rel=1e-6)
