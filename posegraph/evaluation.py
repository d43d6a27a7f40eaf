"""Trajectory error metrics: ATE after alignment and RPE (Sturm et al. 2012, TUM RGB-D
benchmark; Zhang & Scaramuzza 2018, "A Tutorial on Quantitative Trajectory Evaluation").

* ATE: translation error ‖t_gt,k − (S · t_est,k)‖ after aligning the estimate to the ground
  truth with the least-squares SE3 or Sim3 (Umeyama) S, or with no alignment.
* RPE over ``delta`` steps: E_k = (G_k⁻¹ G_{k+δ})⁻¹ (P_k⁻¹ P_{k+δ}); its translation norm and
  rotation angle. RPE needs no alignment (for Sim3 alignment the estimate is rescaled first).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .alignment import umeyama
from .lie import SE3, Sim3
from .trajectory_io import Trajectory


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
class Evaluation:
    """ATE and RPE of an estimate against ground truth, and the alignment used."""

    alignment: str
    alignment_transform: Sim3
    ate: ErrorStatistics
    rpe_translation: ErrorStatistics
    rpe_rotation_deg: ErrorStatistics
    matched: int
    aligned_estimate: SE3

    def as_dict(self) -> dict:
        return {
            "alignment": self.alignment,
            "scale": float(self.alignment_transform.scale),
            "matched_poses": self.matched,
            "ate": dataclasses.asdict(self.ate),
            "rpe_translation": dataclasses.asdict(self.rpe_translation),
            "rpe_rotation_deg": dataclasses.asdict(self.rpe_rotation_deg),
        }


def associate(estimate: Trajectory, truth: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Indices of poses with equal keys in both trajectories (keys match exactly, e.g. ids)."""
    common, index_est, index_gt = np.intersect1d(estimate.keys, truth.keys, return_indices=True)
    return index_est, index_gt


def evaluate(
    estimate: Trajectory, truth: Trajectory, alignment: str = "se3", delta: int = 1
) -> Evaluation:
    """ATE after ``alignment`` ("se3", "sim3" or "none") and RPE over ``delta`` poses."""
    if alignment not in ("se3", "sim3", "none"):
        raise ValueError(f"alignment is 'se3', 'sim3' or 'none', not {alignment!r}")
    index_est, index_gt = associate(estimate, truth)
    if index_est.size < 3:
        raise ValueError(f"only {index_est.size} poses have keys in both trajectories; need ≥ 3")
    if not 1 <= delta < index_est.size:
        raise ValueError(
            f"the RPE step is 1 to {index_est.size - 1} poses (of the {index_est.size} matched), "
            f"not {delta}"
        )
    est, gt = estimate.poses[index_est], truth.poses[index_gt]
    if alignment == "none":
        transform = Sim3.identity()
    else:
        transform = umeyama(est.translation, gt.translation, with_scale=alignment == "sim3")
    s = float(transform.scale)
    aligned = SE3(
        transform.rotation @ est.rotation,
        s * np.einsum("ij,nj->ni", transform.rotation, est.translation) + transform.translation,
    )
    ate = np.linalg.norm(gt.translation - aligned.translation, axis=1)
    relative_gt = gt[:-delta].between(gt[delta:])
    relative_est = aligned[:-delta].between(aligned[delta:])
    error = relative_gt.between(relative_est)
    rpe_t = np.linalg.norm(error.translation, axis=1)
    rpe_r = np.degrees(np.linalg.norm(error.log()[:, 3:], axis=1))
    return Evaluation(
        alignment,
        transform,
        ErrorStatistics.of(ate),
        ErrorStatistics.of(rpe_t),
        ErrorStatistics.of(rpe_r),
        int(index_est.size),
        aligned,
    )
