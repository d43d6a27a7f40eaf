"""Pairing of estimate and ground-truth poses by key, and the ATE over the pairs."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.io.trajectories import Trajectory
from posegraph.lie import SE3
from posegraph.trajectory.evaluation import associate, evaluate


def _trajectory(keys: np.ndarray, seed: int = 0) -> Trajectory:
    return Trajectory(
        np.asarray(keys, float), SE3.sample(np.random.default_rng(seed), (len(keys),))
    )


def _greedy_pairs(estimate_keys, truth_keys, max_difference):
    """The TUM benchmark's associate.py: every pair within max_difference, taken by increasing
    difference, each pose of either side used once."""
    candidates = sorted(
        (abs(a - b), i, j)
        for i, a in enumerate(estimate_keys)
        for j, b in enumerate(truth_keys)
        if abs(a - b) <= max_difference
    )
    used_est, used_gt, pairs = set(), set(), []
    for _, i, j in candidates:
        if i not in used_est and j not in used_gt:
            used_est.add(i)
            used_gt.add(j)
            pairs.append((i, j))
    return sorted(pairs, key=lambda pair: estimate_keys[pair[0]])


def test_time_stamps_pair_as_the_tum_benchmark_pairs_them():
    """A 100 Hz ground truth (shuffled) and a 30 Hz estimate with clock jitter and gaps."""
    rng = np.random.default_rng(4)
    truth_keys = 1305031102.175304 + 0.01 * np.arange(2000)
    truth_keys = truth_keys[rng.permutation(len(truth_keys))]
    estimate_keys = 1305031101.9 + np.arange(0.0, 21.0, 1 / 30) + rng.uniform(-0.01, 0.01, 630)
    estimate_keys = np.delete(estimate_keys, np.arange(100, 140))  # tracking lost
    index_est, index_gt = associate(_trajectory(estimate_keys), _trajectory(truth_keys), 0.02)
    expected = _greedy_pairs(estimate_keys.tolist(), truth_keys.tolist(), 0.02)
    assert list(zip(index_est.tolist(), index_gt.tolist(), strict=True)) == expected
    assert np.all(np.diff(estimate_keys[index_est]) > 0)
    assert 500 < len(expected) < len(estimate_keys)  # the ends outside the ground truth drop


def test_a_ground_truth_pose_pairs_once_with_the_nearest_estimate():
    index_est, index_gt = associate(_trajectory([1.0, 1.004, 1.009]), _trajectory([1.005, 2.0]))
    assert index_est.tolist() == [1] and index_gt.tolist() == [0]


def test_integer_keys_pair_only_when_equal():
    estimate, truth = _trajectory([5, 1, 2, 9, 3]), _trajectory([0, 1, 2, 3, 4, 5, 6])
    index_est, index_gt = associate(estimate, truth)
    assert estimate.keys[index_est].tolist() == [1, 2, 3, 5]
    assert truth.keys[index_gt].tolist() == [1, 2, 3, 5]


def test_ate_of_the_true_poses_at_jittered_stamps_is_zero():
    truth = _trajectory(100.0 + 0.01 * np.arange(500), seed=1)
    picked = np.arange(2, 500, 3)
    jitter = np.random.default_rng(2).uniform(-0.004, 0.004, picked.size)
    estimate = Trajectory(truth.keys[picked] + jitter, truth.poses[picked])
    evaluation = evaluate(estimate, truth)
    assert evaluation.matched == evaluation.estimate_poses == picked.size
    assert evaluation.ate.rmse < 1e-12 and evaluation.rpe_rotation_deg.max < 1e-9
    strict = evaluate(estimate, truth, max_difference=0.001)
    assert strict.matched < picked.size // 2


def test_an_empty_trajectory_pairs_nothing():
    empty, poses = _trajectory([]), _trajectory(np.arange(5))
    for estimate, truth in ((empty, poses), (poses, empty)):
        assert all(index.size == 0 for index in associate(estimate, truth))
        with pytest.raises(ValueError, match="are none"):
            evaluate(estimate, truth)


def test_no_pairs_names_both_key_ranges():
    ids, stamps = _trajectory(np.arange(10)), _trajectory(1305031102.5 + np.arange(10))
    with pytest.raises(
        ValueError,
        match=r"only 0 poses pair .* within 0\.02.* keys run from 0 to 9, the ground truth's run from 1305031102\.5 to 1305031111\.5",
    ):
        evaluate(ids, stamps)


def test_a_scaled_alignment_refuses_a_trajectory_that_stays_at_one_point():
    """Sim3 alignment onto a ground truth that stays at one point shrinks the estimate onto it
    and reported an ATE of 0; a stationary estimate gave NaN. Both are refused by name; a rigid
    alignment of the same pair is well defined (the ATE is the other side's spread)."""
    moving = _trajectory(np.arange(10), seed=3)
    still = Trajectory(moving.keys, SE3(moving.poses.rotation, np.full((10, 3), 2.5)))
    for estimate, truth, name in ((still, moving, "estimate"), (moving, still, "ground truth")):
        with pytest.raises(ValueError, match=f"the {name}'s 10 positions are all at one point"):
            evaluate(estimate, truth, alignment="sim3")
        spread = moving.poses.translation - moving.poses.translation.mean(axis=0)
        rigid = evaluate(estimate, truth, alignment="se3")
        assert rigid.ate.rmse == pytest.approx(np.sqrt(np.mean(np.sum(spread**2, axis=1))))


def _planar(positions_xy: np.ndarray, tilt: SE3 | None = None) -> np.ndarray:
    positions = np.column_stack([positions_xy, np.zeros(len(positions_xy))])
    return positions if tilt is None else tilt.act(positions)


def test_a_planar_estimate_is_told_the_ate_it_cannot_go_below():
    """Ground truth at the corners (±1, ±1) lifted by ±h (z = h·x·y): its least-squares plane
    is z = 0 and its RMS distance from it h, which a planar estimate on the corners reaches."""
    h = 0.1
    corners = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
    truth_positions = np.column_stack([corners, h * corners[:, 0] * corners[:, 1]])
    rotations = np.broadcast_to(np.eye(3), (4, 3, 3))
    keys = np.arange(4.0)
    truth = Trajectory(keys, SE3(rotations, truth_positions))
    estimate = Trajectory(keys, SE3(rotations, _planar(corners)))
    for alignment in ("se3", "sim3", "none"):
        evaluation = evaluate(estimate, truth, alignment)
        assert evaluation.planar_ate_floor == pytest.approx(h, rel=1e-12)
        assert evaluation.ate.rmse == pytest.approx(h, rel=1e-9)


def test_no_alignment_takes_a_planar_estimate_below_the_floor():
    rng = np.random.default_rng(7)
    keys = np.arange(40.0)
    tilt = SE3.sample(rng)
    truth = Trajectory(keys, SE3.sample(rng, (40,)))
    planar_poses = SE3.sample(rng, (40,))
    planar_poses = SE3(planar_poses.rotation, _planar(rng.normal(size=(40, 2)) * 5, tilt))
    estimate = Trajectory(keys, planar_poses)
    for alignment in ("se3", "sim3", "none"):
        evaluation = evaluate(estimate, truth, alignment)
        assert 0 < evaluation.planar_ate_floor <= evaluation.ate.rmse, alignment
    assert evaluate(truth, estimate).planar_ate_floor is None  # the estimate is not planar
    other_plane = _planar(rng.normal(size=(40, 2)), SE3.sample(rng))
    planar_truth = Trajectory(keys, SE3(truth.poses.rotation, other_plane))
    assert evaluate(estimate, planar_truth).planar_ate_floor is None  # both planar


def _straight_line(count: int, rotation: np.ndarray | None = None) -> Trajectory:
    """Poses 1 m apart along x, keyed 0, 1, …; with ``rotation`` (count, 3, 3) as their
    orientations (else the identity)."""
    translation = np.zeros((count, 3))
    translation[:, 0] = np.arange(count)
    if rotation is None:
        rotation = np.tile(np.eye(3), (count, 1, 1))
    return Trajectory(np.arange(count, dtype=float), SE3(rotation, translation))


def test_drift_of_a_stretched_path_is_its_stretch():
    """1001 poses along 1000 m, the estimate 1% longer and not aligned: a segment of length L
    runs from pose f (every 10th) to pose f + L + 1, the first whose distance exceeds L (the
    KITTI devkit's rule), so its translation error is 1% of L + 1 m, and its rotation error 0.
    Starts up to 999 − L fit. Pooled, the lengths weigh by their segments. Sim3 alignment
    removes the stretch."""
    truth = _straight_line(1001)
    stretched = Trajectory(truth.keys, SE3(truth.poses.rotation, 1.01 * truth.poses.translation))
    drift = evaluate(stretched, truth, "none").drift_by_length
    lengths = np.arange(100.0, 900.0, 100.0)
    assert [d.lengths for d in drift] == [(length,) for length in lengths]
    counts = [d.segments for d in drift]
    assert counts == [(999 - int(length)) // 10 + 1 for length in lengths]
    expected = (lengths + 1) / lengths  # per cent
    np.testing.assert_allclose([d.translation_percent for d in drift], expected, rtol=1e-9)
    np.testing.assert_allclose([d.rotation_deg_per_100m for d in drift], 0.0, atol=1e-12)
    pooled = evaluate(stretched, truth, "none").drift
    assert pooled.segments == sum(counts)
    assert pooled.translation_percent == pytest.approx(np.average(expected, weights=counts))
    aligned = evaluate(stretched, truth, "sim3").drift
    assert aligned.translation_percent < 1e-9


def test_drift_of_a_turning_heading_is_its_rate():
    """The estimate's heading turns 0.001 rad per pose where the truth's stays: a segment of
    L + 1 poses turns by 0.001 (L + 1) rad, which per 100 m of L is the rotation drift."""
    rate, truth = 0.001, _straight_line(1001)
    yaw = rate * np.arange(1001)
    rotation = np.zeros((1001, 3, 3))
    rotation[:, 0, 0] = rotation[:, 1, 1] = np.cos(yaw)
    rotation[:, 0, 1], rotation[:, 1, 0] = -np.sin(yaw), np.sin(yaw)
    rotation[:, 2, 2] = 1.0
    turning = _straight_line(1001, rotation)
    drift = evaluate(turning, truth, "none", segment_lengths=(100.0, 400.0)).drift_by_length
    for d, length in zip(drift, (100.0, 400.0), strict=True):
        assert d.rotation_deg_per_100m == pytest.approx(
            100.0 * np.degrees(rate * (length + 1) / length), rel=1e-9
        )


def test_no_segment_fits_a_path_shorter_than_every_length():
    """A 50 m path has no drift over KITTI's 100–800 m; over 10 and 20 m it has. Lengths must
    be positive."""
    truth = _straight_line(51)
    assert evaluate(truth, truth).drift is None
    assert evaluate(truth, truth).drift_by_length == ()
    short = evaluate(truth, truth, segment_lengths=(10.0, 20.0, 100.0))
    assert short.drift.lengths == (10.0, 20.0) and short.drift.translation_percent < 1e-12
    assert short.segment_lengths == (10.0, 20.0, 100.0)
    with pytest.raises(ValueError, match=r"segment lengths must be positive, not \[10.0, 0.0\]"):
        evaluate(truth, truth, segment_lengths=(10.0, 0.0))
    with pytest.raises(ValueError, match=r"segment lengths must be positive, not \[\]"):
        evaluate(truth, truth, segment_lengths=())
