"""SO(2): planar rotations, stored as an angle in (−π, π]. Tangent: (θ). Eade §2."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._coeffs import wrap_angle
from .base import LieGroup


def rotation_matrix_2d(angle: np.ndarray) -> np.ndarray:
    """The (…, 2, 2) rotation matrix of an angle array."""
    angle = np.asarray(angle, float)
    c, s = np.cos(angle), np.sin(angle)
    out = np.empty(angle.shape + (2, 2))
    out[..., 0, 0] = out[..., 1, 1] = c
    out[..., 0, 1] = -s
    out[..., 1, 0] = s
    return out


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class SO2(LieGroup):
    """Rotations of the plane; ``angle`` has the batch shape."""

    angle: np.ndarray

    dof: ClassVar[int] = 1
    matrix_size: ClassVar[int] = 2
    point_dim: ClassVar[int] = 2
    _event_ndims: ClassVar[dict[str, int]] = {"angle": 0}

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()) -> SO2:
        return cls(np.zeros(batch_shape))

    @classmethod
    def exp(cls, tangent: np.ndarray) -> SO2:
        return cls(wrap_angle(np.asarray(tangent, float)[..., 0]))

    def log(self) -> np.ndarray:
        return wrap_angle(self.angle)[..., None]

    def compose(self, other: SO2) -> SO2:
        return SO2(wrap_angle(self.angle + other.angle))

    def inverse(self) -> SO2:
        return SO2(wrap_angle(-self.angle))

    def as_matrix(self) -> np.ndarray:
        return rotation_matrix_2d(self.angle)

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> SO2:
        matrix = np.asarray(matrix, float)
        return cls(np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0]))

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> SO2:
        return cls(rng.uniform(-np.pi, np.pi, batch_shape))

    @classmethod
    def generators(cls) -> np.ndarray:
        return np.array([[[0.0, -1.0], [1.0, 0.0]]])

    def normalize(self) -> SO2:
        return SO2(wrap_angle(self.angle))

    def adjoint(self) -> np.ndarray:
        """Ad = 1: SO(2) is abelian."""
        return np.ones(self.batch_shape + (1, 1))

    @classmethod
    def ad(cls, tangent: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(tangent)[:-1] + (1, 1))

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        """jr = 1: SO(2) is abelian."""
        return np.ones(np.shape(tangent)[:-1] + (1, 1))

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        return cls.jr(tangent)
