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
    """The similarity (R, t, s) mapping ``source`` points (N, 3) onto ``target`` (N, 3).

    Umeyama eqs. 34–42: with the cross-covariance Σ = (1/N) Σₖ (yₖ − μ_y)(xₖ − μ_x)ᵀ = U D Vᵀ and
    S = diag(1, 1, det(U)det(V)): R = U S Vᵀ, s = tr(D S)/σ_x², t = μ_y − s R μ_x.
    With scale, a point set with no spread (σ² ≤ 1e-24 of its mean square) is refused, naming
    it by ``names``: s would be 0/0 for the source, and 0 for the target, which shrinks the
    source onto one point and makes every error vanish.
    """
    source, target = np.asarray(source, float), np.asarray(target, float)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"need two (N, 3) point sets, got {source.shape} and {target.shape}")
    if source.shape[0] < 3:
        raise ValueError(f"need at least 3 point pairs to align, got {source.shape[0]}")
    mu_x, mu_y = source.mean(axis=0), target.mean(axis=0)
    x, y = source - mu_x, target - mu_y
    covariance = y.T @ x / source.shape[0]
    u, d, vt = np.linalg.svd(covariance)
    sign = np.diag([1.0, 1.0, np.sign(np.linalg.det(u) * np.linalg.det(vt))])
    rotation = u @ sign @ vt
    variance = _mean_square(x)
    if with_scale:
        for points, centered, name in ((source, x, names[0]), (target, y, names[1])):
            if not _mean_square(centered) > 1e-24 * _mean_square(points):
                raise ValueError(
                    f"the {name}'s {len(points)} positions are all at one point, so an alignment "
                    "with scale (sim3) is undefined; align without scale (se3)"
                )
    scale = float(np.trace(np.diag(d) @ sign) / variance) if with_scale else 1.0
    translation = mu_y - scale * rotation @ mu_x
    return Sim3(rotation, translation, scale)


def _mean_square(points: np.ndarray) -> float:
    """(1/N) Σₖ ‖pₖ‖² of (N, 3) points."""
    return float(np.mean(np.sum(points * points, axis=1)))


def as_se3(similarity: Sim3) -> SE3:
    """The rigid part (R, t) of a similarity (meaningful when s = 1)."""
    return SE3(similarity.rotation, similarity.translation)
