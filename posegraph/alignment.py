"""Least-squares alignment of point sets: Umeyama (1991), "Least-squares estimation of
transformation parameters between two point patterns" (Horn 1987 in closed form).

Finds (R, t, s) minimising Σ ‖yₖ − (s R xₖ + t)‖²; with ``with_scale=False``, s = 1 (SE3).
"""

from __future__ import annotations

import numpy as np

from .lie import SE3, Sim3


def umeyama(
    source: np.ndarray,
    target: np.ndarray,
    with_scale: bool = True,
    names: tuple[str, str] = ("source", "target"),
) -> Sim3:
    """The similarity (R, t, s) mapping ``source`` points (N, 3) onto ``target`` (N, 3)
    (``similarity_fit`` with equal weights).

    With scale, a point set with no spread (σ² ≤ 1e-24 of its mean square) is refused, naming
    it by ``names``: s would be 0/0 for the source, and 0 for the target, which shrinks the
    source onto one point and makes every error vanish.
    """
    source, target = np.asarray(source, float), np.asarray(target, float)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"need two (N, 3) point sets, got {source.shape} and {target.shape}")
    if source.shape[0] < 3:
        raise ValueError(f"need at least 3 point pairs to align, got {source.shape[0]}")
    if with_scale:
        for points, name in ((source, names[0]), (target, names[1])):
            if not _mean_square(points - points.mean(axis=0)) > 1e-24 * _mean_square(points):
                raise ValueError(
                    f"the {name}'s {len(points)} positions are all at one point, so an alignment "
                    "with scale (sim3) is undefined; align without scale (se3)"
                )
    rotation, translation, scale = similarity_fit(source, target, np.ones(len(source)), with_scale)
    return Sim3(rotation, translation, scale)


def similarity_fit(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray, with_scale: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, t, s) minimising Σₖ wₖ ‖yₖ − (s R xₖ + t)‖² over (N, d) points, any d, with weights
    wₖ ≥ 0 of positive sum; s = 1 without scale.

    Umeyama eqs. 34–42, weighted: with μ = Σₖ wₖ pₖ / Σₖ wₖ, the cross-covariance
    Σ = Σₖ wₖ (yₖ − μ_y)(xₖ − μ_x)ᵀ / Σₖ wₖ = U D Vᵀ and S = diag(1, …, 1, det(U)det(V)):
    R = U S Vᵀ, s = tr(D S)/σ_x², t = μ_y − s R μ_x. Points with no spread give R = I.
    """
    weights = weights / weights.sum()
    mu_x, mu_y = weights @ source, weights @ target
    x, y = source - mu_x, target - mu_y
    u, d, vt = np.linalg.svd((weights[:, None] * y).T @ x)
    sign = np.ones(source.shape[1])
    sign[-1] = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    rotation = u @ np.diag(sign) @ vt
    scale = float(d @ sign / (weights @ np.sum(x * x, axis=1))) if with_scale else 1.0
    return rotation, mu_y - scale * rotation @ mu_x, scale


def _mean_square(points: np.ndarray) -> float:
    """(1/N) Σₖ ‖pₖ‖² of (N, d) points."""
    return float(np.mean(np.sum(points * points, axis=1)))


def as_se3(similarity: Sim3) -> SE3:
    """The rigid part (R, t) of a similarity (meaningful when s = 1)."""
    return SE3(similarity.rotation, similarity.translation)
