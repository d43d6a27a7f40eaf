"""SE(3): rigid motions, stored as rotation R (…, 3, 3) and translation t (…, 3).

Tangent (ρ, φ), translation first. Exp/Log: Eade §3.2 (t = V ρ with V = jl(φ) of SO(3)).
Right Jacobian: Barfoot §7.1.5, eq. 7.86 (the Q matrix), taken at −ξ since jr(ξ) = jl(−ξ).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from . import _coeffs
from ._coeffs import hat3, so3_polynomial, so3_polynomial_apply
from .base import LieGroup
from .so3 import (
    angle,
    jr_inv_matrix,
    jr_matrix,
    log_with_trig,
    matrix_to_quaternion,
    project_to_rotation,
    quaternion_to_matrix,
    sample_rotation,
)


def _q_right(rho: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Barfoot's Q(−ρ, −φ): the upper-right block of the SE(3) right Jacobian.

    Eq. 7.86 at (−ρ, −φ) is Σ of products of ρ× and φ×. With s = φ·ρ, u = φ × ρ and the
    identities a× b× = b aᵀ − (a·b) I and (a × b)× = b aᵀ − a bᵀ, every product reduces to
    I, φ×, φ×², ρ×, (u × φ)× and ρφᵀ + φρᵀ:
    Q = −2c₁s I + (c₁ − c₂)s φ× − 2c₃s φ×² + (c₂ (u × φ) − ½ρ)× + c₁ (ρφᵀ + φρᵀ),
    where c₁, c₂, c₃ are the coefficients of eq. 7.86 (``se3_q_coefficients``).
    """
    rho, phi = np.asarray(rho, float), np.asarray(phi, float)
    c1, c2, c3 = _coeffs.se3_q_coefficients(angle(phi))
    s = np.einsum("...i,...i->...", phi, rho)
    u = _coeffs.cross(phi, rho)
    outer = rho[..., :, None] * phi[..., None, :]
    return (
        so3_polynomial(phi, -2.0 * c1 * s, (c1 - c2) * s, -2.0 * c3 * s)
        + hat3(c2[..., None] * _coeffs.cross(u, phi) - 0.5 * rho)
        + c1[..., None, None] * (outer + np.swapaxes(outer, -1, -2))
    )


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class SE3(LieGroup):
    """Poses ``p ↦ R p + t``."""

    rotation: np.ndarray
    translation: np.ndarray

    dof: ClassVar[int] = 6
    matrix_size: ClassVar[int] = 4
    point_dim: ClassVar[int] = 3
    _event_ndims: ClassVar[dict[str, int]] = {"rotation": 2, "translation": 1}

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()) -> SE3:
        return cls(
            np.broadcast_to(np.eye(3), batch_shape + (3, 3)).copy(), np.zeros(batch_shape + (3,))
        )

    @classmethod
    def exp(cls, tangent: np.ndarray) -> SE3:
        """R = Exp(φ), t = V ρ with V = jl(φ) = I + ((1 − cos θ)/θ²) φ× + ((θ − sin θ)/θ³) φ×²."""
        tangent = np.asarray(tangent, float)
        rho, phi = tangent[..., :3], tangent[..., 3:]
        a, b, c = _coeffs.rotation_coefficients(angle(phi))
        t = so3_polynomial_apply(phi, 1.0, b, c, rho)
        return cls(so3_polynomial(phi, 1.0, a, b), t)

    def log(self) -> np.ndarray:
        """φ = Log R, ρ = V⁻¹ t with V⁻¹ = jl⁻¹(φ) = I − ½ φ× + c(θ) φ×²."""
        phi, theta, sin, cos = log_with_trig(self.rotation)
        c = _coeffs.so3_jr_inv_coefficient_from_trig(theta, sin, cos)
        translation = np.broadcast_to(self.translation, phi.shape)
        rho = so3_polynomial_apply(phi, 1.0, -0.5, c, translation)
        return np.concatenate([rho, phi], axis=-1)

    def compose(self, other: SE3) -> SE3:
        t = np.einsum("...ij,...j->...i", self.rotation, other.translation) + self.translation
        return SE3(self.rotation @ other.rotation, t)

    def inverse(self) -> SE3:
        r_t = np.swapaxes(self.rotation, -1, -2)
        return SE3(r_t, -np.einsum("...ij,...j->...i", r_t, self.translation))

    def as_matrix(self) -> np.ndarray:
        m = np.zeros(self.batch_shape + (4, 4))
        m[..., :3, :3] = self.rotation
        m[..., :3, 3] = self.translation
        m[..., 3, 3] = 1.0
        return m

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> SE3:
        matrix = np.asarray(matrix, float)
        return cls(matrix[..., :3, :3], matrix[..., :3, 3])

    @classmethod
    def from_quaternion_translation(cls, quaternion: np.ndarray, translation: np.ndarray) -> SE3:
        """From (…, 4) quaternions (x, y, z, w) and (…, 3) translations."""
        return cls(quaternion_to_matrix(quaternion), translation)

    def as_quaternion_translation(self) -> tuple[np.ndarray, np.ndarray]:
        """(…, 4) quaternions (x, y, z, w) with w ≥ 0, and (…, 3) translations."""
        return matrix_to_quaternion(self.rotation), np.broadcast_to(
            self.translation, self.batch_shape + (3,)
        )

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> SE3:
        return cls(sample_rotation(rng, batch_shape), rng.normal(size=batch_shape + (3,)))

    @classmethod
    def generators(cls) -> np.ndarray:
        g = np.zeros((6, 4, 4))
        g[:3, :3, 3] = np.eye(3)
        g[3:, :3, :3] = hat3(np.eye(3))
        return g

    def normalize(self) -> SE3:
        return SE3(project_to_rotation(self.rotation), self.translation)

    def adjoint(self) -> np.ndarray:
        """Ad = [[R, t× R], [0, R]] (Eade eq. 98, translation first)."""
        ad = np.zeros(self.batch_shape + (6, 6))
        ad[..., :3, :3] = self.rotation
        ad[..., :3, 3:] = hat3(self.translation) @ self.rotation
        ad[..., 3:, 3:] = self.rotation
        return ad

    @classmethod
    def ad(cls, tangent: np.ndarray) -> np.ndarray:
        """ad(ρ, φ) = [[φ×, ρ×], [0, φ×]]."""
        tangent = np.asarray(tangent, float)
        p, r = hat3(tangent[..., 3:]), hat3(tangent[..., :3])
        ad = np.zeros(tangent.shape[:-1] + (6, 6))
        ad[..., :3, :3] = p
        ad[..., :3, 3:] = r
        ad[..., 3:, 3:] = p
        return ad

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        """jr(ρ, φ) = [[jr(φ), Q(−ρ, −φ)], [0, jr(φ)]]."""
        tangent = np.asarray(tangent, float)
        rho, phi = tangent[..., :3], tangent[..., 3:]
        j = jr_matrix(phi)
        out = np.zeros(tangent.shape[:-1] + (6, 6))
        out[..., :3, :3] = j
        out[..., 3:, 3:] = j
        out[..., :3, 3:] = _q_right(rho, phi)
        return out

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        """jr⁻¹ = [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]] with J = jr(φ), Q = Q(−ρ, −φ)."""
        tangent = np.asarray(tangent, float)
        rho, phi = tangent[..., :3], tangent[..., 3:]
        j_inv = jr_inv_matrix(phi)
        out = np.zeros(tangent.shape[:-1] + (6, 6))
        out[..., :3, :3] = j_inv
        out[..., 3:, 3:] = j_inv
        out[..., :3, 3:] = -j_inv @ _q_right(rho, phi) @ j_inv
        return out
