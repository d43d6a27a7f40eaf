"""Gaussian uncertainty on Lie groups (Eade §8; Barfoot & Furgale 2014), for every group.

A Gaussian on a group is a mean X̄ and a covariance Σ of δ in ``X = X̄ · Exp(δ)`` (right
perturbation, CONVENTIONS.md). Eade perturbs on the left; each formula below is his, moved to
the right with ``Exp(δ) · X = X · Exp(Ad(X⁻¹) δ)``.
"""

from __future__ import annotations

import numpy as np

from .base import LieGroup


def _sandwich(a: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    return a @ covariance @ np.swapaxes(a, -1, -2)


def compose_covariance(
    x: LieGroup,
    covariance_x: np.ndarray,
    y: LieGroup,
    covariance_y: np.ndarray,
    cross_covariance: np.ndarray | None = None,
) -> np.ndarray:
    """Covariance of Z = X · Y when both factors are uncertain (Eade §8.2, eq. 42).

    ``X̄ Exp(δx) Ȳ Exp(δy) ≈ X̄Ȳ Exp(Ad(Ȳ⁻¹) δx + δy)``, so with A = Ad(Ȳ⁻¹) and
    C = E[δx δyᵀ]: Σ_Z = A Σx Aᵀ + Σy + A C + Cᵀ Aᵀ.
    """
    a = y.inverse().adjoint()
    covariance = _sandwich(a, covariance_x) + covariance_y
    if cross_covariance is not None:
        ac = a @ cross_covariance
        covariance = covariance + ac + np.swapaxes(ac, -1, -2)
    return covariance


def inverse_covariance(x: LieGroup, covariance: np.ndarray) -> np.ndarray:
    """Covariance of X⁻¹ (Eade §8.3): ``(X̄ Exp(δ))⁻¹ = X̄⁻¹ Exp(−Ad(X̄) δ)``, Σ' = Ad Σ Adᵀ."""
    return _sandwich(x.adjoint(), covariance)


def fuse(
    x1: LieGroup,
    covariance1: np.ndarray,
    x2: LieGroup,
    covariance2: np.ndarray,
    max_iterations: int = 20,
    tolerance: float = 1e-12,
) -> tuple[LieGroup, np.ndarray]:
    """Bayesian fusion of two Gaussian estimates of one element (Eade §8.4, eqs. 48–52).

    Gauss-Newton on Σᵢ ½ rᵢᵀ Σᵢ⁻¹ rᵢ with rᵢ = Log(Xᵢ⁻¹ X) and ∂rᵢ/∂δ = jr⁻¹(rᵢ); the fused
    covariance is the inverse of the final information Σᵢ Jᵢᵀ Σᵢ⁻¹ Jᵢ.
    """
    estimates = [(x1, np.linalg.inv(covariance1)), (x2, np.linalg.inv(covariance2))]
    x = x1
    for _ in range(max_iterations):
        information, gradient = 0.0, 0.0
        for estimate, weight in estimates:
            r = estimate.local(x)
            j = x.jr_inv(r)
            jt_w = np.swapaxes(j, -1, -2) @ weight
            information = information + jt_w @ j
            gradient = gradient + np.einsum("...ij,...j->...i", jt_w, r)
        step = -np.linalg.solve(information, gradient[..., None])[..., 0]
        x = x.retract(step)
        if np.max(np.abs(step)) < tolerance:
            break
    information = 0.0
    for estimate, weight in estimates:
        j = x.jr_inv(estimate.local(x))
        information = information + np.swapaxes(j, -1, -2) @ weight @ j
    return x, np.linalg.inv(information)


def mean_and_covariance(
    samples: LieGroup, max_iterations: int = 50, tolerance: float = 1e-12
) -> tuple[LieGroup, np.ndarray]:
    """The intrinsic mean and covariance of samples along batch axis 0 (Eade §8.5).

    Iterates X̄ ← X̄ · Exp(mean_k Log(X̄⁻¹ X_k)); the covariance is mean_k r_k r_kᵀ (1/N) of the
    final residuals r_k = Log(X̄⁻¹ X_k).
    """
    mean = samples[0]
    for _ in range(max_iterations):
        residuals = mean.local(samples)
        step = residuals.mean(axis=0)
        mean = mean.retract(step)
        if np.max(np.abs(step)) < tolerance:
            break
    residuals = mean.local(samples)
    covariance = np.einsum("k...i,k...j->...ij", residuals, residuals) / residuals.shape[0]
    return mean, covariance


def sample_gaussian(
    mean: LieGroup, covariance: np.ndarray, rng: np.random.Generator, count: int
) -> LieGroup:
    """``count`` draws of X̄ · Exp(δ), δ ~ N(0, Σ); the result has batch shape (count, …)."""
    chol = np.linalg.cholesky(covariance)
    z = rng.normal(size=(count,) + mean.batch_shape + (mean.dof,))
    return mean.retract(np.einsum("...ij,...j->...i", chol, z))
