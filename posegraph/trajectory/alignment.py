"""Least-squares alignment of point sets: Umeyama (1991), "Least-squares estimation of
transformation parameters between two point patterns" (Horn 1987 in closed form).

Finds (R, t, s) minimising Σ ‖yₖ − (s R xₖ + t)‖²; with ``with_scale=False``, s = 1 (SE3).
"""

from __future__ import annotations

import numpy as np

from ..lie import SE3, Sim3
from ..lie.so3 import svd_of_finite


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
    source onto one point and makes every error vanish. Positions whose squares overflow
    (beyond about 1e154) are refused too.
    """
    source, target = np.asarray(source, float), np.asarray(target, float)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"need two (N, 3) point sets, got {source.shape} and {target.shape}")
    if source.shape[0] < 3:
        raise ValueError(f"need at least 3 point pairs to align, got {source.shape[0]}")
    with np.errstate(over="ignore"):
        squares_overflow = not np.isfinite(_mean_square(source) + _mean_square(target))
    if squares_overflow:
        largest = max(np.abs(source).max(), np.abs(target).max())
        raise ValueError(
            f"the {names[0]} and {names[1]} positions (up to {largest:.3g}) are too large to "
            "align: their squares overflow double precision"
        )
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
    wₖ ≥ 0 of positive sum; s = 1 without scale (``similarity_fits`` of one group)."""
    rotation, translation, scale = similarity_fits(
        source, target, weights, np.zeros(len(source), dtype=np.int64), 1, with_scale
    )
    return rotation[0], translation[0], float(scale[0])


def similarity_fits(
    source: np.ndarray,
    target: np.ndarray,
    weights: np.ndarray,
    groups: np.ndarray,
    count: int,
    with_scale: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``similarity_fit`` of every group of points at once: (R (count, d, d), t (count, d),
    s (count,)) fitting the points k with ``groups[k]`` = g; each group's weights have a
    positive sum, and a group with no points gets the identity.

    Umeyama eqs. 34–42, weighted: with μ = Σₖ wₖ pₖ / Σₖ wₖ, the cross-covariance
    Σ = Σₖ wₖ (yₖ − μ_y)(xₖ − μ_x)ᵀ / Σₖ wₖ = U D Vᵀ and S = diag(1, …, 1, det(U)det(V)):
    R = U S Vᵀ, s = tr(D S)/σ_x², t = μ_y − s R μ_x. Points with no spread give R = I. A
    group whose sums overflow (positions beyond about 1e154) gets NaN.
    """
    d = source.shape[1]
    share = weights / np.bincount(groups, weights, count)[groups]

    def group_sums(terms: np.ndarray) -> np.ndarray:
        columns = terms.reshape(len(terms), int(np.prod(terms.shape[1:]))).T
        sums = np.stack([np.bincount(groups, column, count) for column in columns], axis=-1)
        return sums.reshape((count,) + terms.shape[1:])

    with np.errstate(over="ignore", invalid="ignore"):  # overflow: NaN (``umeyama`` refuses it)
        mu_x, mu_y = group_sums(share[:, None] * source), group_sums(share[:, None] * target)
        x, y = source - mu_x[groups], target - mu_y[groups]
        cross = group_sums(share[:, None, None] * y[:, :, None] * x[:, None])
        u, singular, vt = svd_of_finite(cross)
        sign = np.ones((count, d))
        sign[:, -1] = np.sign(np.linalg.det(u) * np.linalg.det(vt))
        rotation = (u * sign[:, None, :]) @ vt
        scale = np.ones(count)
        if with_scale:
            scale = np.sum(singular * sign, axis=1) / group_sums(share * np.sum(x * x, axis=1))
        return rotation, mu_y - scale[:, None] * np.einsum("gij,gj->gi", rotation, mu_x), scale


def _mean_square(points: np.ndarray) -> float:
    """(1/N) Σₖ ‖pₖ‖² of (N, d) points."""
    return float(np.mean(np.sum(points * points, axis=1)))


def as_se3(similarity: Sim3) -> SE3:
    """The rigid part (R, t) of a similarity (meaningful when s = 1)."""
    return SE3(similarity.rotation, similarity.translation)
