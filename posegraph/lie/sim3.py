"""Sim(3): similarities ``p ↦ s R p + t``, stored normalised as (R, t, s) (CONVENTIONS.md).

Tangent (ρ, φ, σ) with σ = log s; the algebra element is [[φ× + σI, ρ], [0, 0]]. This is
Eade's Sim(3) (§6) under the isomorphism t = s·t_E, with (u, ω, λ) = (ρ, φ, σ).

Exp (Eade §6.2): R = Exp(φ), s = e^σ, t = W ρ with W = ∫₀¹ e^{σu} Exp(uφ) du = a I + b φ× + c φ×²:
    a = ∫₀¹ e^{σu} du,  b = ∫₀¹ e^{σu} sin(uθ)/θ du,  c = ∫₀¹ e^{σu} (1 − cos uθ)/θ² du.
For θ ≥ 1 they are evaluated in closed form; below, by their series in θ, whose terms are the
moments m_k(σ) = ∫₀¹ e^{σu} u^k du.

Left Jacobian, by differentiating Exp (ξ + dξ) = Exp(δ) Exp(ξ) to first order in δ, with t = W ρ:
    jl(ξ) = [[W, ∂(Wρ)/∂φ + t× jl(φ), ∂(Wρ)/∂σ − t], [0, jl(φ), 0], [0, 0, 1]],
where jl(φ) is SO(3)'s, ∂(Wρ)/∂σ = a_σ ρ + b_σ φ×ρ + c_σ φ×²ρ and
    ∂(Wρ)/∂φ = −b ρ× + c ((φ·ρ) I + φρᵀ − 2ρφᵀ) + (b_θ φ×ρ + c_θ φ×²ρ) φᵀ/θ,
from φ×²ρ = φ(φ·ρ) − θ²ρ. The right Jacobian is jr(ξ) = jl(−ξ).
"""

from __future__ import annotations

import dataclasses
from math import factorial
from typing import ClassVar

import numpy as np

from ._coeffs import cross, hat3, powers, series_terms, so3_polynomial, so3_polynomial_apply
from .base import LieGroup
from .so3 import (
    angle,
    exp_matrix,
    jr_inv_matrix,
    jr_matrix,
    log_matrix,
    matrix_to_quaternion,
    project_to_rotation,
    quaternion_to_matrix,
    sample_rotation,
)

_THETA_SERIES_BELOW = 1.0
_THETA_TERMS = 11  # θ^{2·11} / 23! < 1e-22 for θ < 1
_SIGMA_SERIES_BELOW = 20.0
_SIGMA_TERMS = 90  # 20^90 / 90! < 1e-20


def _series_weights(offset: int, derivative: bool) -> list[float]:
    """Weights w_j of θ²ʲ in Σⱼ (−1)ʲ θ²ʲ m/(2j + offset)!, or with ``derivative`` in its
    derivative in θ divided by θ: the weight of θ²ʲ there is (−1)ʲ⁺¹ 2(j + 1)/(2j + 2 + offset)!."""
    if derivative:
        return [
            (-1.0) ** (j + 1) * 2 * (j + 1) / factorial(2 * j + 2 + offset)
            for j in range(_THETA_TERMS)
        ]
    return [(-1.0) ** j / factorial(2 * j + offset) for j in range(_THETA_TERMS)]


_SERIES_FIRST_MOMENTS = np.array([1, 2, 2, 3, 3, 4])
_SERIES_WEIGHTS = np.array(
    [
        _series_weights(1, False),
        _series_weights(2, False),
        _series_weights(1, False),
        _series_weights(2, False),
        _series_weights(1, True),
        _series_weights(2, True),
    ]
)
"""W's coefficients for θ < 1 as Σⱼ wⱼ θ²ʲ m_{first+2j}, one row per coefficient: b and c
(b = Σⱼ (−1)ʲ θ²ʲ m_{2j+1}/(2j+1)!, c = Σⱼ (−1)ʲ θ²ʲ m_{2j+2}/(2j+2)!), their derivatives in σ
(∂m_k/∂σ = m_{k+1}), and their derivatives in θ divided by θ."""
_TOP_MOMENT = int(_SERIES_FIRST_MOMENTS.max()) + 2 * (_THETA_TERMS - 1)


def _sigma_terms(largest: float) -> int:
    """The terms of a moment's series in σ that |σ| ≤ ``largest`` (< 20) needs: up to the first
    σⁿ/n! below 1e-20, as ``_SIGMA_TERMS`` is for |σ| < 20."""
    return series_terms(lambda n: largest**n / factorial(n), 1e-20, _SIGMA_TERMS)


def _theta_terms(largest: float) -> int:
    """The terms of W's series in θ² that θ ≤ ``largest`` (< 1) needs: up to the first
    θ²ʲ/(2j+1)! below 1e-22, as ``_THETA_TERMS`` is for θ < 1."""
    return series_terms(lambda j: largest ** (2 * j) / factorial(2 * j + 1), 1e-22, _THETA_TERMS)


_MOMENT_SERIES = (
    np.array(
        [
            [1.0 / (factorial(n) * (n + k + 1)) for n in range(_SIGMA_TERMS)]
            for k in range(_TOP_MOMENT + 1)
        ]
    ),
    np.array(
        [
            [factorial(k) / factorial(n + k + 1) for n in range(_SIGMA_TERMS)]
            for k in range(_TOP_MOMENT + 1)
        ]
    ),
)
"""Coefficients of |σ|ⁿ (columns) in m_k(σ) (rows) = Σₙ σⁿ/(n! (n + k + 1)) for σ ≥ 0, and in
m_k(σ) e^{−σ} = Σₙ k! |σ|ⁿ/(n + k + 1)! for σ < 0 (Kummer's transformation of ₁F₁): every term
positive, so each moment is summed without cancellation."""


def _moments(sigma: np.ndarray, top: int) -> np.ndarray:
    """(top + 1, …) array of m_k(σ) = ∫₀¹ e^{σu} u^k du, k ≤ top.

    For |σ| < 20 each by its series (``_MOMENT_SERIES``), as one matrix product with the powers
    of |σ|. Above, by the recurrence σ m_k = e^σ − k m_{k−1} upward from m_0 = (e^σ − 1)/σ,
    which is stable there.
    """
    below = np.abs(sigma) < _SIGMA_SERIES_BELOW
    s = np.where(below, sigma, 0.0)
    x = np.abs(s)
    terms = _sigma_terms(x.max(initial=0.0))
    positive, negative = (series[: top + 1, :terms] @ powers(x, terms) for series in _MOMENT_SERIES)
    moments = np.where(s < 0.0, negative * np.exp(s), positive)
    if below.all():
        return moments
    s = np.where(below, _SIGMA_SERIES_BELOW, sigma)
    e = np.exp(s)
    upward = [np.expm1(s) / s]
    for k in range(1, top + 1):
        upward.append((e - k * upward[-1]) / s)
    return np.where(below, moments, np.array(upward))


def _small_angle_coefficients(
    sigma: np.ndarray, theta: np.ndarray, a: np.ndarray, derivatives: bool
) -> list[np.ndarray]:
    """W's coefficients but a, for θ < 1, from their series in θ² (``_SERIES_WEIGHTS``), whose
    terms are the moments; ∂a/∂σ = m_1."""
    rows = 6 if derivatives else 2
    terms = _theta_terms(float(theta.max(initial=0.0)))
    indices = _SERIES_FIRST_MOMENTS[:rows, None] + 2 * np.arange(terms)
    moments = _moments(sigma, int(indices.max()))
    theta_powers = powers(theta * theta, terms)
    sums = list(
        np.einsum(
            "sj,j...,sj...->s...", _SERIES_WEIGHTS[:rows, :terms], theta_powers, moments[indices]
        )
    )
    if not derivatives:
        return sums
    return [*sums[:2], moments[1], *sums[2:]]


def _large_angle_coefficients(
    sigma: np.ndarray, theta: np.ndarray, a: np.ndarray, derivatives: bool
) -> list[np.ndarray]:
    """W's coefficients but a, for θ ≥ 1, in closed form, from z = σ + iθ:
    E = ∫₀¹ e^{zu} du = (e^z − 1)/z gives b = Im E/θ, c = (a − Re E)/θ², and
    E' = ∫₀¹ u e^{zu} du = (e^z (z − 1) + 1)/z² their derivatives (∂E/∂σ = E', ∂E/∂θ = iE').
    For σ < 0 the weight e^{σu} sits near u = 0, where (∂c/∂θ)/θ cancels most: against exact
    references it is within 4e-14 relative at σ = −1 and −8, and 2e-11 at σ = −20 (the other
    coefficients within 1e-13 down to σ = −25; Sim3's Jacobians, which weigh it little, within
    7e-15)."""
    z = sigma + 1j * theta
    e = np.exp(z)
    integral = (e - 1.0) / z
    t2 = theta * theta
    b = integral.imag / theta
    c = (a - integral.real) / t2
    if not derivatives:
        return [b, c]
    a_sigma = _moments(sigma, 1)[1]
    moment = (e * (z - 1.0) + 1.0) / (z * z)
    return [
        b,
        c,
        a_sigma,
        moment.imag / theta,
        (a_sigma - moment.real) / t2,
        (moment.real - b) / t2,
        (moment.imag / theta - 2.0 * c) / t2,
    ]


def _coefficients(sigma: np.ndarray, theta: np.ndarray, derivatives: bool) -> list[np.ndarray]:
    """[a, b, c] or with ``derivatives`` as ``w_derivatives``; a = (e^σ − 1)/σ = m_0."""
    sigma, theta = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(theta, float))
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(sigma == 0.0, 1.0, np.expm1(sigma) / sigma)
    small = theta < _THETA_SERIES_BELOW
    out = [np.empty_like(theta) for _ in range(7 if derivatives else 2)]
    for part, evaluate in ((small, _small_angle_coefficients), (~small, _large_angle_coefficients)):
        if np.any(part):
            for array, value in zip(
                out, evaluate(sigma[part], theta[part], a[part], derivatives), strict=True
            ):
                array[part] = value
    return [a, *out]


def w_coefficients(sigma: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """(a, b, c) of W = a I + b φ× + c φ×² for σ and θ = |φ| (module docstring)."""
    return tuple(_coefficients(sigma, theta, derivatives=False))


def w_derivatives(sigma: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """(a, b, c, ∂a/∂σ, ∂b/∂σ, ∂c/∂σ, (∂b/∂θ)/θ, (∂c/∂θ)/θ) of W's coefficients."""
    return tuple(_coefficients(sigma, theta, derivatives=True))


def w_inverse_coefficients(a: np.ndarray, b: np.ndarray, c: np.ndarray, theta: np.ndarray):
    """(α, β, γ) with W⁻¹ = α I + β φ× + γ φ×², from φ×³ = −θ² φ×.

    With d = a − θ² c and Δ = d² + θ² b²: α = 1/a, β = −b/Δ, γ = (b² − c d)/(a Δ).
    """
    t2 = theta * theta
    d = a - t2 * c
    delta = d * d + t2 * b * b
    return 1.0 / a, -b / delta, (b * b - c * d) / (a * delta)


def _left_jacobian_blocks(tangent: np.ndarray) -> tuple[np.ndarray, ...]:
    """(a, b, c) of W, t = Wρ, ∂t/∂φ (…, 3, 3) and jl's last column's top ∂t/∂σ − t (…, 3), at
    ξ = (ρ, φ, σ) (module docstring)."""
    rho, phi, sigma = tangent[..., :3], tangent[..., 3:6], tangent[..., 6]
    a, b, c, a_sigma, b_sigma, c_sigma, b_theta, c_theta = w_derivatives(sigma, angle(phi))
    phi_rho = cross(phi, rho)
    phi2_rho = cross(phi, phi_rho)
    translation = a[..., None] * rho + b[..., None] * phi_rho + c[..., None] * phi2_rho
    by_scale = (
        a_sigma[..., None] * rho
        + b_sigma[..., None] * phi_rho
        + c_sigma[..., None] * phi2_rho
        - translation
    )
    # c φρᵀ + (b_θ φ×ρ + c_θ φ×²ρ − 2cρ) φᵀ as one product of (…, 3, 2) by (…, 2, 3).
    along_phi = (
        b_theta[..., None] * phi_rho + c_theta[..., None] * phi2_rho - 2.0 * c[..., None] * rho
    )
    by_rotation = np.stack([c[..., None] * phi, along_phi], axis=-1) @ np.stack([rho, phi], axis=-2)
    by_rotation += hat3(-b[..., None] * rho)
    diagonal = c * np.einsum("...i,...i->...", phi, rho)
    for k in range(3):
        by_rotation[..., k, k] += diagonal
    return (a, b, c), translation, by_rotation, by_scale


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
        """From N = [[sR, t], [0, 1]]; a general last row is normalised away first. The scale
        is ∛det(sR), taken through log|det| so that s³ may lie beyond double precision."""
        matrix = np.asarray(matrix, float)
        matrix = matrix / matrix[..., 3:, 3:]
        linear = matrix[..., :3, :3]
        sign, log_determinant = np.linalg.slogdet(linear)
        scale = sign * np.exp(log_determinant / 3.0)
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

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        """jr(ξ) = jl(−ξ) in closed form (module docstring); φ below is −ξ's."""
        negated = -np.asarray(tangent, float)
        phi = negated[..., 3:6]
        w, translation, by_rotation, by_scale = _left_jacobian_blocks(negated)
        rotation_jacobian = jr_matrix(-phi)  # SO(3)'s jl(φ)
        out = np.zeros(negated.shape[:-1] + (7, 7))
        out[..., :3, :3] = so3_polynomial(phi, *w)
        out[..., :3, 3:6] = by_rotation + hat3(translation) @ rotation_jacobian
        out[..., :3, 6] = by_scale
        out[..., 3:6, 3:6] = rotation_jacobian
        out[..., 6, 6] = 1.0
        return out

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        """jr⁻¹(ξ) = jl(−ξ)⁻¹ by blocks: [[W⁻¹, −W⁻¹ (∂t/∂φ jl(φ)⁻¹ + t×), −W⁻¹ (∂t/∂σ − t)],
        [0, jl(φ)⁻¹, 0], [0, 0, 1]] at −ξ, with W⁻¹ from ``w_inverse_coefficients`` and SO(3)'s
        jl⁻¹ in closed form."""
        negated = -np.asarray(tangent, float)
        phi = negated[..., 3:6]
        w, translation, by_rotation, by_scale = _left_jacobian_blocks(negated)
        w_inverse = so3_polynomial(phi, *w_inverse_coefficients(*w, angle(phi)))
        rotation_inverse = jr_inv_matrix(-phi)  # SO(3)'s jl(φ)⁻¹
        out = np.zeros(negated.shape[:-1] + (7, 7))
        out[..., :3, :3] = w_inverse
        out[..., :3, 3:6] = -w_inverse @ (by_rotation @ rotation_inverse + hat3(translation))
        out[..., :3, 6] = -np.einsum("...ij,...j->...i", w_inverse, by_scale)
        out[..., 3:6, 3:6] = rotation_inverse
        out[..., 6, 6] = 1.0
        return out
