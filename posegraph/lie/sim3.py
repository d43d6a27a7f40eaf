"""Sim(3): similarities ``p ↦ s R p + t``, stored normalised as (R, t, s) (CONVENTIONS.md).

Tangent (ρ, φ, σ) with σ = log s; the algebra element is [[φ× + σI, ρ], [0, 0]]. This is
Eade's Sim(3) (§6) under the isomorphism t = s·t_E, with (u, ω, λ) = (ρ, φ, σ).

Exp (Eade §6.2): R = Exp(φ), s = e^σ, t = W ρ with W = ∫₀¹ e^{σu} Exp(uφ) du = a I + b φ× + c φ×²:
    a = ∫₀¹ e^{σu} du,  b = ∫₀¹ e^{σu} sin(uθ)/θ du,  c = ∫₀¹ e^{σu} (1 − cos uθ)/θ² du.
For θ ≥ 0.5 they are evaluated in closed form; below, by their series in θ, whose terms are the
moments m_k(σ) = ∫₀¹ e^{σu} u^k du. The right Jacobian is the base class's exact integral.
"""

from __future__ import annotations

import dataclasses
from math import factorial
from typing import ClassVar

import numpy as np

from ._coeffs import hat3, so3_polynomial_apply
from .base import LieGroup
from .so3 import (
    angle,
    exp_matrix,
    log_matrix,
    matrix_to_quaternion,
    project_to_rotation,
    quaternion_to_matrix,
    sample_rotation,
)

_THETA_SERIES_BELOW = 0.5
_THETA_TERMS = 9  # θ^{2·9} / 19! < 1e-20 for θ < 0.5
_SIGMA_SERIES_BELOW = 8.0
_SIGMA_TERMS = 51  # 8^51 / 51! < 1e-20


_MOMENTS = 2 * _THETA_TERMS
_TOP_MOMENT_SERIES = np.array(
    [1.0 / (factorial(n) * (n + _MOMENTS + 1)) for n in range(_SIGMA_TERMS)]
)
"""Coefficient of σⁿ in the series of m_K(σ), K = ``_MOMENTS``."""
_MOMENT_WEIGHTS = [(-1.0) ** ((k - 1) // 2) / factorial(k) for k in range(_MOMENTS + 1)]
"""(−1)ʲ/k! for k = 2j+1 and k = 2j+2: the weight of θ²ʲ m_k in b (k odd) and in c (k even)."""


def _sigma_terms(largest: float) -> int:
    """The terms of m_K's series in σ that |σ| ≤ ``largest`` (< 8) needs: up to the first
    σⁿ/n! below 1e-20, as ``_SIGMA_TERMS`` is for |σ| < 8."""
    term = 1.0
    for n in range(1, _SIGMA_TERMS):
        term *= largest / n
        if term < 1e-20:
            return n
    return _SIGMA_TERMS


def _small_angle_coefficients(sigma: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """(b, c) for θ < 0.5 from their series b = Σⱼ (−1)ʲ θ²ʲ m_{2j+1}(σ)/(2j+1)! and
    c = Σⱼ (−1)ʲ θ²ʲ m_{2j+2}(σ)/(2j+2)!, j < ``_THETA_TERMS``, in the moments
    m_k(σ) = ∫₀¹ e^{σu} u^k du, which satisfy σ m_k = e^σ − k m_{k−1}.

    For |σ| < 8 the moments run downward from the series of the top one,
    m_K = Σₙ σⁿ / (n! (n + K + 1)): an error in m_K reaches m_k times |σ|^{K−k} k!/K!, at most
    0.35 for k ≥ 1. Above, they run upward from m_0 = (e^σ − 1)/σ, which is stable there.
    """
    t2 = theta * theta
    below = np.abs(sigma) < _SIGMA_SERIES_BELOW
    s = np.where(below, sigma, 0.0)
    e = np.exp(s)
    moment = np.zeros_like(s)
    for coefficient in _TOP_MOMENT_SERIES[_sigma_terms(np.abs(s).max(initial=0.0)) - 1 :: -1]:
        moment = moment * s + coefficient
    b, c = np.zeros_like(s), np.zeros_like(s)
    for k in range(_MOMENTS, 0, -1):  # Horner in θ², from the highest power down
        if k % 2:
            b = b * t2 + _MOMENT_WEIGHTS[k] * moment
        else:
            c = c * t2 + _MOMENT_WEIGHTS[k] * moment
        moment = (e - s * moment) / k
    if below.all():
        return b, c
    s = np.where(below, _SIGMA_SERIES_BELOW, sigma)
    e = np.exp(s)
    moment, power = np.expm1(s) / s, np.ones_like(s)
    b_up, c_up = np.zeros_like(s), np.zeros_like(s)
    for k in range(1, _MOMENTS + 1):
        moment = (e - k * moment) / s
        if k % 2:
            b_up += _MOMENT_WEIGHTS[k] * power * moment
        else:
            c_up += _MOMENT_WEIGHTS[k] * power * moment
            power = power * t2
    return np.where(below, b, b_up), np.where(below, c, c_up)


def w_coefficients(sigma: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """(a, b, c) of W = a I + b φ× + c φ×² for σ and θ = |φ| (module docstring)."""
    sigma, theta = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(theta, float))
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(sigma == 0.0, 1.0, np.expm1(sigma) / sigma)
    small = theta < _THETA_SERIES_BELOW
    b = np.empty_like(theta)
    c = np.empty_like(theta)
    if np.any(small):
        b[small], c[small] = _small_angle_coefficients(sigma[small], theta[small])
    large = ~small
    if np.any(large):
        s, t, a_l = sigma[large], theta[large], a[large]
        e = np.exp(s)
        denominator = s * s + t * t
        integral_sin = (e * (s * np.sin(t) - t * np.cos(t)) + t) / denominator
        integral_cos = (e * (s * np.cos(t) + t * np.sin(t)) - s) / denominator
        b[large] = integral_sin / t
        c[large] = (a_l - integral_cos) / (t * t)
    return a, b, c


def w_inverse_coefficients(a: np.ndarray, b: np.ndarray, c: np.ndarray, theta: np.ndarray):
    """(α, β, γ) with W⁻¹ = α I + β φ× + γ φ×², from φ×³ = −θ² φ×.

    With d = a − θ² c and Δ = d² + θ² b²: α = 1/a, β = −b/Δ, γ = (b² − c d)/(a Δ).
    """
    t2 = theta * theta
    d = a - t2 * c
    delta = d * d + t2 * b * b
    return 1.0 / a, -b / delta, (b * b - c * d) / (a * delta)


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Sim3(LieGroup):
    """Similarities ``p ↦ s R p + t`` with matrix N = [[sR, t], [0, 1]]."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: np.ndarray

    dof: ClassVar[int] = 7
    matrix_size: ClassVar[int] = 4
    point_dim: ClassVar[int] = 3
    _event_ndims: ClassVar[dict[str, int]] = {"rotation": 2, "translation": 1, "scale": 0}

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()) -> Sim3:
        rotation = np.broadcast_to(np.eye(3), batch_shape + (3, 3)).copy()
        return cls(rotation, np.zeros(batch_shape + (3,)), np.ones(batch_shape))

    @classmethod
    def exp(cls, tangent: np.ndarray) -> Sim3:
        tangent = np.asarray(tangent, float)
        rho, phi, sigma = tangent[..., :3], tangent[..., 3:6], tangent[..., 6]
        t = so3_polynomial_apply(phi, *w_coefficients(sigma, angle(phi)), rho)
        return cls(exp_matrix(phi), t, np.exp(sigma))

    def log(self) -> np.ndarray:
        phi = log_matrix(self.rotation)
        theta = angle(phi)
        sigma = np.broadcast_to(np.log(self.scale), theta.shape)
        inverse = w_inverse_coefficients(*w_coefficients(sigma, theta), theta)
        rho = so3_polynomial_apply(phi, *inverse, np.broadcast_to(self.translation, phi.shape))
        return np.concatenate([rho, phi, sigma[..., None]], axis=-1)

    def compose(self, other: Sim3) -> Sim3:
        rotated = np.einsum("...ij,...j->...i", self.rotation, other.translation)
        return Sim3(
            self.rotation @ other.rotation,
            self.scale[..., None] * rotated + self.translation,
            self.scale * other.scale,
        )

    def inverse(self) -> Sim3:
        r_t = np.swapaxes(self.rotation, -1, -2)
        t = -np.einsum("...ij,...j->...i", r_t, self.translation) / self.scale[..., None]
        return Sim3(r_t, t, 1.0 / self.scale)

    def as_matrix(self) -> np.ndarray:
        m = np.zeros(self.batch_shape + (4, 4))
        m[..., :3, :3] = self.scale[..., None, None] * self.rotation
        m[..., :3, 3] = self.translation
        m[..., 3, 3] = 1.0
        return m

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> Sim3:
        """From N = [[sR, t], [0, 1]]; a general last row is normalised away first."""
        matrix = np.asarray(matrix, float)
        matrix = matrix / matrix[..., 3:, 3:]
        linear = matrix[..., :3, :3]
        scale = np.cbrt(np.linalg.det(linear))
        return cls(linear / scale[..., None, None], matrix[..., :3, 3], scale)

    @classmethod
    def from_quaternion_translation_scale(
        cls, quaternion: np.ndarray, translation: np.ndarray, scale: np.ndarray
    ) -> Sim3:
        """From (…, 4) quaternions (x, y, z, w), (…, 3) translations and (…) scales."""
        return cls(quaternion_to_matrix(quaternion), translation, scale)

    def as_quaternion(self) -> np.ndarray:
        """(…, 4) unit quaternions (x, y, z, w) of the rotation, w ≥ 0."""
        return matrix_to_quaternion(self.rotation)

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> Sim3:
        return cls(
            sample_rotation(rng, batch_shape),
            rng.normal(size=batch_shape + (3,)),
            np.exp(rng.normal(scale=0.5, size=batch_shape)),
        )

    @classmethod
    def generators(cls) -> np.ndarray:
        g = np.zeros((7, 4, 4))
        g[:3, :3, 3] = np.eye(3)
        g[3:6, :3, :3] = hat3(np.eye(3))
        g[6, :3, :3] = np.eye(3)
        return g

    def normalize(self) -> Sim3:
        return Sim3(project_to_rotation(self.rotation), self.translation, self.scale)

    def adjoint(self) -> np.ndarray:
        """Ad = [[sR, t× R, −t], [0, R, 0], [0, 0, 1]]."""
        ad = np.zeros(self.batch_shape + (7, 7))
        ad[..., :3, :3] = self.scale[..., None, None] * self.rotation
        ad[..., :3, 3:6] = hat3(self.translation) @ self.rotation
        ad[..., :3, 6] = -self.translation
        ad[..., 3:6, 3:6] = self.rotation
        ad[..., 6, 6] = 1.0
        return ad

    @classmethod
    def ad(cls, tangent: np.ndarray) -> np.ndarray:
        """ad(ρ, φ, σ) = [[φ× + σI, ρ×, −ρ], [0, φ×, 0], [0, 0, 0]]."""
        tangent = np.asarray(tangent, float)
        rho, phi, sigma = tangent[..., :3], tangent[..., 3:6], tangent[..., 6]
        ad = np.zeros(tangent.shape[:-1] + (7, 7))
        ad[..., :3, :3] = hat3(phi) + sigma[..., None, None] * np.eye(3)
        ad[..., :3, 3:6] = hat3(rho)
        ad[..., :3, 6] = -rho
        ad[..., 3:6, 3:6] = hat3(phi)
        return ad
