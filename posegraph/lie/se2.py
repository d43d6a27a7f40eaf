"""SE(2): rigid motions of the plane, stored as (angle θ, translation t). Tangent (x, y, θ).

Exp and Log: Eade §3.2. The right Jacobian is the closed form of Chirikjian vol. 2 §10.6
(also manif's ``SE2::rjac``), written here in the coefficients of ``_coeffs``.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from . import _coeffs
from .base import LieGroup
from .so2 import rotation_matrix_2d

_J = np.array([[0.0, -1.0], [1.0, 0.0]])


def _rotated(angle: np.ndarray, points: np.ndarray) -> np.ndarray:
    """R(θ) p for (…) angles and (…, 2) points, elementwise (no batched matrix product)."""
    cos, sin = np.cos(angle), np.sin(angle)
    x, y = points[..., 0], points[..., 1]
    return np.stack([cos * x - sin * y, sin * x + cos * y], axis=-1)


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class SE2(LieGroup):
    """Planar poses ``p ↦ R(θ) p + t``."""

    angle: np.ndarray
    translation: np.ndarray

    dof: ClassVar[int] = 3
    matrix_size: ClassVar[int] = 3
    point_dim: ClassVar[int] = 2
    _event_ndims: ClassVar[dict[str, int]] = {"angle": 0, "translation": 1}

    @property
    def rotation_matrix(self) -> np.ndarray:
        """The (…, 2, 2) rotation part."""
        return rotation_matrix_2d(self.angle)

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()) -> SE2:
        return cls(np.zeros(batch_shape), np.zeros(batch_shape + (2,)))

    @classmethod
    def from_xytheta(cls, xytheta: np.ndarray) -> SE2:
        """From (…, 3) arrays of (x, y, θ) as in g2o's VERTEX_SE2 (not the exponential map)."""
        xytheta = np.asarray(xytheta, float)
        return cls(_coeffs.wrap_angle(xytheta[..., 2]), xytheta[..., :2])

    def as_xytheta(self) -> np.ndarray:
        """The (…, 3) array of (x, y, θ)."""
        t = np.broadcast_to(self.translation, self.batch_shape + (2,))
        return np.concatenate([t, np.broadcast_to(self.angle, self.batch_shape)[..., None]], -1)

    @classmethod
    def exp(cls, tangent: np.ndarray) -> SE2:
        tangent = np.asarray(tangent, float)
        rho, theta = tangent[..., :2], tangent[..., 2]
        # V(θ) = a I + b J with a = sin θ / θ, b = (1 − cos θ) / θ (Eade eq. 69).
        a, one_minus_cos_over_sq, _ = _coeffs.rotation_coefficients(theta)
        b = theta * one_minus_cos_over_sq
        t = a[..., None] * rho + b[..., None] * (rho @ _J.T)
        return cls(_coeffs.wrap_angle(theta), t)

    def log(self) -> np.ndarray:
        theta = _coeffs.wrap_angle(self.angle)
        # V⁻¹ = (θ/2) cot(θ/2) I − (θ/2) J (Eade eq. 74).
        a = _coeffs.half_cot_half(theta)[..., None]
        t = np.broadcast_to(self.translation, self.batch_shape + (2,))
        rho = a * t - 0.5 * theta[..., None] * (t @ _J.T)
        return np.concatenate([rho, theta[..., None]], axis=-1)

    def compose(self, other: SE2) -> SE2:
        t = _rotated(self.angle, other.translation)
        return SE2(_coeffs.wrap_angle(self.angle + other.angle), self.translation + t)

    def inverse(self) -> SE2:
        t = -_rotated(-self.angle, self.translation)
        return SE2(_coeffs.wrap_angle(-self.angle), t)

    def between(self, other: SE2) -> SE2:
        """X⁻¹ Y = (θ_Y − θ_X, R(θ_X)ᵀ (t_Y − t_X)) in one pass: one cos and sin, no
        intermediate inverse."""
        t = _rotated(-self.angle, other.translation - self.translation)
        return SE2(_coeffs.wrap_angle(other.angle - self.angle), t)

    def as_matrix(self) -> np.ndarray:
        batch = self.batch_shape
        m = np.zeros(batch + (3, 3))
        m[..., :2, :2] = self.rotation_matrix
        m[..., :2, 2] = self.translation
        m[..., 2, 2] = 1.0
        return m

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> SE2:
        matrix = np.asarray(matrix, float)
        return cls(np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0]), matrix[..., :2, 2])

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> SE2:
        return cls(rng.uniform(-np.pi, np.pi, batch_shape), rng.normal(size=batch_shape + (2,)))

    @classmethod
    def generators(cls) -> np.ndarray:
        g = np.zeros((3, 3, 3))
        g[0, 0, 2] = g[1, 1, 2] = 1.0
        g[2, :2, :2] = _J
        return g

    def normalize(self) -> SE2:
        return SE2(_coeffs.wrap_angle(self.angle), self.translation)

    def adjoint(self) -> np.ndarray:
        """Ad = [[R, −J t], [0, 1]] (Eade eq. 79, with translation first)."""
        batch = self.batch_shape
        ad = np.zeros(batch + (3, 3))
        ad[..., :2, :2] = self.rotation_matrix
        ad[..., :2, 2] = -(self.translation @ _J.T)
        ad[..., 2, 2] = 1.0
        return ad

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        """jr(ρ, θ) = [[a I − b J, w], [0, 1]], a and b those of V(θ), w = (c x − d y, d x + c y),
        c = (θ − sin θ)/θ², d = (1 − cos θ)/θ² (Chirikjian vol. 2 §10.6; manif SE2::rjac)."""
        tangent = np.asarray(tangent, float)
        x, y, theta = tangent[..., 0], tangent[..., 1], tangent[..., 2]
        a, d, theta_minus_sin_over_cube = _coeffs.rotation_coefficients(theta)
        b, c = theta * d, theta * theta_minus_sin_over_cube
        jr = np.zeros(tangent.shape[:-1] + (3, 3))
        jr[..., 0, 0] = a
        jr[..., 0, 1] = b
        jr[..., 1, 0] = -b
        jr[..., 1, 1] = a
        jr[..., 0, 2] = c * x - d * y
        jr[..., 1, 2] = d * x + c * y
        jr[..., 2, 2] = 1.0
        return jr

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        """Inverse of jr = [[A, w], [0, 1]]: [[A⁻¹, −A⁻¹ w], [0, 1]], where A = a I − b J, so
        A⁻¹ = (a I + b J)/(a² + b²)."""
        tangent = np.asarray(tangent, float)
        x, y, theta = tangent[..., 0], tangent[..., 1], tangent[..., 2]
        a, d, theta_minus_sin_over_cube = _coeffs.rotation_coefficients(theta)
        b, c = theta * d, theta * theta_minus_sin_over_cube
        w_x, w_y = c * x - d * y, d * x + c * y
        norm = a * a + b * b
        a, b = a / norm, b / norm
        out = np.zeros(tangent.shape[:-1] + (3, 3))
        out[..., 0, 0] = out[..., 1, 1] = a
        out[..., 0, 1] = -b
        out[..., 1, 0] = b
        out[..., 0, 2] = b * w_y - a * w_x
        out[..., 1, 2] = -(b * w_x + a * w_y)
        out[..., 2, 2] = 1.0
        return out
