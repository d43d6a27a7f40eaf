"""Trajectory error metrics: ATE after alignment and RPE (Sturm et al. 2012, TUM RGB-D
benchmark; Zhang & Scaramuzza 2018, "A Tutorial on Quantitative Trajectory Evaluation").

* ATE: translation error ‖t_gt,k − (S · t_est,k)‖ after aligning the estimate to the ground
  truth with the least-squares SE3 or Sim3 (Umeyama) S, or with no alignment.
* RPE over ``delta`` steps: E_k = (G_k⁻¹ G_{k+δ})⁻¹ (P_k⁻¹ P_{k+δ}); its translation norm and
  rotation angle. RPE needs no alignment (for Sim3 alignment the estimate is rescaled first).
* Poses are paired by key: a TUM file's time stamps, a graph's node ids, a KITTI file's line
  numbers. Time stamps of two sensors rarely agree, so a pair may differ by up to
  ``max_difference`` (``MAX_KEY_DIFFERENCE``, as the benchmark's ``associate.py``).
* A planar estimate (a 2D graph, lifted to z = 0) cannot follow a ground truth that leaves its
  plane: whatever the alignment, its ATE RMSE is at least the ground truth's RMS distance from
  its least-squares plane, which is reported.
* Drift over path segments, the KITTI odometry benchmark's metric (Geiger, Lenz & Urtasun
  2012; its devkit's ``evaluate_odometry.cpp``): ``segment_drift``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..io.trajectories import Trajectory
from ..lie import SE3, Sim3
from .alignment import umeyama

KITTI_SEGMENT_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
"""The KITTI odometry benchmark's segment lengths, in the trajectories' unit (metres)."""

KITTI_STEP = 10
"""Segments start at every 10th pose, as the KITTI devkit's."""

MAX_KEY_DIFFERENCE = 0.02
"""Largest key difference of a pair: 0.02 s of time stamps, the TUM RGB-D benchmark's default.
Integer keys (node ids, KITTI lines) then pair only when equal."""


@dataclasses.dataclass(frozen=True)
class ErrorStatistics:
    rmse: float
    mean: float
    median: float
    max: float
    count: int

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStatistics:
        errors = np.asarray(errors, float)
        return cls(
            float(np.sqrt(np.mean(errors**2))),
            float(errors.mean()),
            float(np.median(errors)),
            float(errors.max()),
            int(errors.size),
        )


@dataclasses.dataclass(frozen=True)
class Drift:
    """Relative error per unit of path over segments (``segment_drift``): the translation
    error as a percentage of the segment's length, the rotation error in degrees per 100
    units, averaged over ``segments`` segments of the ``lengths``."""

    lengths: tuple[float, ...]
    segments: int
    translation_percent: float
    rotation_deg_per_100m: float


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """ATE, RPE and drift over path segments of an estimate against ground truth, and the
    alignment used."""

    alignment: str
    alignment_transform: Sim3
    ate: ErrorStatistics
    rpe_translation: ErrorStatistics
    rpe_rotation_deg: ErrorStatistics
    matched: int
    estimate_poses: int
    max_difference: float
    aligned_estimate: SE3
    planar_ate_floor: float | None
    """When the estimate is planar and the ground truth is not (``planar_ate_floor``), the
    lowest ATE RMSE that a planar estimate can reach; else None."""
    segment_lengths: tuple[float, ...]
    drift_by_length: tuple[Drift, ...]
    """Per length that a segment fits (``segment_drift``)."""
    matched_truth: SE3
    """The ground-truth poses paired with ``aligned_estimate``'s, in its order."""
    ate_errors: np.ndarray
    """Each paired pose's translation error after alignment (what ``ate`` summarises)."""

    @property
    def distance_travelled(self) -> np.ndarray:
        """Path length along the paired ground truth up to each pose (for errors over
        distance)."""
        steps = np.linalg.norm(np.diff(self.matched_truth.translation, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    @property
    def drift(self) -> Drift | None:
        """Over the segments of all lengths together (the KITTI devkit's average), or None
        where no segment fits in the ground truth's path."""
        return _pooled(self.drift_by_length)

    def as_dict(self) -> dict:
        return {
            "alignment": self.alignment,
            "scale": float(self.alignment_transform.scale),
            "matched_poses": self.matched,
            "estimate_poses": self.estimate_poses,
            "max_time_difference": self.max_difference,
            "ate": dataclasses.asdict(self.ate),
            "rpe_translation": dataclasses.asdict(self.rpe_translation),
            "rpe_rotation_deg": dataclasses.asdict(self.rpe_rotation_deg),
            "planar_ate_floor": self.planar_ate_floor,
            "segment_lengths": list(self.segment_lengths),
            "drift": None if self.drift is None else dataclasses.asdict(self.drift),
            "drift_by_length": [dataclasses.asdict(d) for d in self.drift_by_length],
        }


def paired_by_index(estimate: Trajectory, truth: Trajectory) -> tuple[Trajectory, Trajectory]:
    """The first n poses of each, n the shorter's length, keyed 0 … n−1, so that they pair by
    index whatever their keys."""
    count = min(len(estimate.keys), len(truth.keys))
    keys = np.arange(count)
    return Trajectory(keys, estimate.poses[:count]), Trajectory(keys, truth.poses[:count])


def associate(
    estimate: Trajectory, truth: Trajectory, max_difference: float = MAX_KEY_DIFFERENCE
) -> tuple[np.ndarray, np.ndarray]:
    """Indices (into the estimate, into the truth) of the pairs, in the order of the estimate's
    keys. Each estimate pose pairs with the ground-truth pose of the nearest key, if they differ
    by at most ``max_difference``; a ground-truth pose claimed by several keeps the nearest."""
    if not len(truth.keys) or not len(estimate.keys):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(truth.keys, kind="stable")
    keys = truth.keys[order]
    after = np.searchsorted(keys, estimate.keys).clip(max=len(keys) - 1)
    before = (after - 1).clip(min=0)
    before_gap, after_gap = (np.abs(keys[k] - estimate.keys) for k in (before, after))
    nearest = np.where(after_gap < before_gap, after, before)
    gap = np.minimum(before_gap, after_gap)
    near = np.flatnonzero(gap <= max_difference)
    near = near[np.argsort(gap[near], kind="stable")]
    claimed = near[np.unique(nearest[near], return_index=True)[1]]
    index_est = claimed[np.argsort(estimate.keys[claimed], kind="stable")]
    return index_est, order[nearest[index_est]]


def _key_range(keys: np.ndarray) -> str:
    return f"run from {keys.min():.15g} to {keys.max():.15g}" if len(keys) else "are none"


def evaluate(
    estimate: Trajectory,
    truth: Trajectory,
    alignment: str = "se3",
    delta: int = 1,
    max_difference: float = MAX_KEY_DIFFERENCE,
    segment_lengths: tuple[float, ...] = KITTI_SEGMENT_LENGTHS,
) -> Evaluation:
    """ATE after ``alignment`` ("se3", "sim3" or "none"), RPE over ``delta`` poses and the drift
    over path segments of ``segment_lengths`` (``segment_drift``), over the poses paired by
    ``associate``."""
    if alignment not in ("se3", "sim3", "none"):
        raise ValueError(f"alignment is 'se3', 'sim3' or 'none', not {alignment!r}")
    if not max_difference >= 0:
        raise ValueError(f"the largest key difference must be 0 or more, not {max_difference}")
    if not segment_lengths or not all(length > 0 for length in segment_lengths):
        raise ValueError(f"segment lengths must be positive, not {list(segment_lengths)}")
    index_est, index_gt = associate(estimate, truth, max_difference)
    if index_est.size < 3:
        raise ValueError(
            f"only {index_est.size} poses pair with a ground-truth pose whose key (time stamp, "
            f"node id or KITTI line) is within {max_difference:g}; need ≥ 3. The estimate's "
            f"keys {_key_range(estimate.keys)}, the ground truth's {_key_range(truth.keys)}"
        )
    if not 1 <= delta < index_est.size:
        raise ValueError(
            f"the RPE step is 1 to {index_est.size - 1} poses (of the {index_est.size} matched), "
            f"not {delta}"
        )
    est, gt = estimate.poses[index_est], truth.poses[index_gt]
    transform, aligned = _aligned(est, gt, alignment)
    ate = np.linalg.norm(gt.translation - aligned.translation, axis=1)
    steps = np.arange(index_est.size - delta)
    rpe_t, rpe_r = relative_pose_errors(gt, aligned, steps, steps + delta)
    return Evaluation(
        alignment,
        transform,
        ErrorStatistics.of(ate),
        ErrorStatistics.of(rpe_t),
        ErrorStatistics.of(np.degrees(rpe_r)),
        int(index_est.size),
        len(estimate.keys),
        max_difference,
        aligned,
        planar_ate_floor(est.translation, gt.translation),
        tuple(float(length) for length in segment_lengths),
        tuple(segment_drift(gt, aligned, segment_lengths)),
        gt,
        ate,
    )


def _aligned(est: SE3, gt: SE3, alignment: str) -> tuple[Sim3, SE3]:
    """The transform that aligns the estimate's positions to the ground truth's (Umeyama, with
    scale for "sim3"; the identity for "none"), and the estimate's poses moved by it."""
    if alignment == "none":
        transform = Sim3.identity()
    else:
        transform = umeyama(
            est.translation,
            gt.translation,
            with_scale=alignment == "sim3",
            names=("estimate", "ground truth"),
        )
    s = float(transform.scale)
    aligned = SE3(
        transform.rotation @ est.rotation,
        s * np.einsum("ij,nj->ni", transform.rotation, est.translation) + transform.translation,
    )
    return transform, aligned


def relative_pose_errors(
    truth: SE3, estimate: SE3, start: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per pair of indices, the translation norm and rotation angle (radians) of the error
    between the motions Δ = X_start⁻¹ X_end of the truth and of the estimate: Δ_gt⁻¹ Δ_est (the
    RPE's), whose norm and angle are those of its inverse Δ_est⁻¹ Δ_gt (the KITTI devkit's)."""
    error = truth[start].between(truth[end]).between(estimate[start].between(estimate[end]))
    return np.linalg.norm(error.translation, axis=1), np.linalg.norm(error.log()[:, 3:], axis=1)


def segment_drift(
    truth: SE3, estimate: SE3, lengths: tuple[float, ...] = KITTI_SEGMENT_LENGTHS
) -> list[Drift]:
    """Per segment length L, the KITTI odometry benchmark's errors (its devkit's
    ``calcSequenceErrors``): from every ``KITTI_STEP``-th pose f, the first later pose l whose
    distance along the ground truth's path from f exceeds L; of E = Δ_est⁻¹ Δ_gt, Δ = X_f⁻¹ X_l,
    the translation ‖t_E‖ / L and the rotation angle ∠R_E / L, averaged over those segments.
    Lengths that no segment fits (the path is shorter) are left out."""
    path = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(truth.translation, axis=0), axis=1))]
    )
    first = np.arange(0, len(path), KITTI_STEP)
    drift = []
    for length in lengths:
        last = np.searchsorted(path, path[first] + length, side="right")
        start, end = first[last < len(path)], last[last < len(path)]
        if not start.size:
            continue
        translation, rotation = relative_pose_errors(truth, estimate, start, end)
        drift.append(
            Drift(
                (float(length),),
                int(start.size),
                100.0 * float(translation.mean()) / length,
                100.0 * float(np.degrees(rotation.mean())) / length,
            )
        )
    return drift


def _pooled(by_length: tuple[Drift, ...]) -> Drift | None:
    """The drift over the segments of every length together (the KITTI devkit's average), or
    None if there are none."""
    if not by_length:
        return None
    weights = np.array([d.segments for d in by_length], float)

    def mean(values) -> float:
        return float(np.average(values, weights=weights))

    return Drift(
        tuple(length for d in by_length for length in d.lengths),
        int(weights.sum()),
        mean([d.translation_percent for d in by_length]),
        mean([d.rotation_deg_per_100m for d in by_length]),
    )


PLANAR_TOLERANCE = 1e-9
"""Points lie in a plane when the smallest singular value of their centred coordinates is at
most this times the largest."""


def planar_ate_floor(estimate_positions: np.ndarray, truth_positions: np.ndarray) -> float | None:
    """The RMS distance of ``truth_positions`` (n × 3) from their least-squares plane, when
    ``estimate_positions`` lie in a plane and they do not; else None.

    Any rigid or similarity transform keeps the estimate in some plane P, and
    Σₖ ‖gₖ − eₖ‖² ≥ Σₖ dist(gₖ, P)² ≥ σ₃², the smallest singular value of the centred gₖ
    squared (the least-squares plane's sum of squared distances), so σ₃ / √n bounds the ATE
    RMSE from below, under any alignment.
    """

    def singular_values(points: np.ndarray) -> np.ndarray:
        return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)

    def planar(singular: np.ndarray) -> bool:
        return bool(singular[2] <= PLANAR_TOLERANCE * singular[0])

    truth_singular = singular_values(truth_positions)
    if not planar(singular_values(estimate_positions)) or planar(truth_singular):
        return None
    return float(truth_singular[2] / np.sqrt(len(truth_positions)))
