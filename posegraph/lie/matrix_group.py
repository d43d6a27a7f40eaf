"""Groups handled through their matrices alone: Aff(2) and SL(3) (Dellaert 2016, §8–9).

Exp is the matrix exponential of ``hat(ξ)``; Log the principal matrix logarithm. Adjoint, ad and
the Jacobians come from the generators through the base class. These groups are not on any hot
path: Log calls ``scipy.linalg.logm`` element by element, because an eigen-decomposition fails
on the defective matrices (pure translations, shears) these groups contain.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .base import LieGroup


def _unit(n: int, i: int, j: int) -> np.ndarray:
    e = np.zeros((n, n))
    e[i, j] = 1.0
    return e


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class MatrixGroup(LieGroup):
    """A matrix Lie group stored as its (…, n, n) matrices."""

    matrix: np.ndarray

    _event_ndims: ClassVar[dict[str, int]] = {"matrix": 2}

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()):
        n = cls.matrix_size
        return cls(np.broadcast_to(np.eye(n), batch_shape + (n, n)).copy())

    @classmethod
    def exp(cls, tangent: np.ndarray):
        import scipy.linalg  # on use: the command line's start does without it

        return cls(scipy.linalg.expm(cls.hat(tangent)))

    def log(self) -> np.ndarray:
        import scipy.linalg

        n = self.matrix_size
        flat = self.matrix.reshape(-1, n, n)
        logs = np.stack([np.real(scipy.linalg.logm(m)) for m in flat])
        return self.vee(logs.reshape(self.matrix.shape))

    def compose(self, other):
        return type(self)(self.matrix @ other.matrix)

    def inverse(self):
        return type(self)(np.linalg.inv(self.matrix))

    def as_matrix(self) -> np.ndarray:
        return self.matrix

    @classmethod
    def from_matrix(cls, matrix: np.ndarray):
        return cls(matrix).normalize()

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()):
        return cls.exp(0.5 * rng.normal(size=batch_shape + (cls.dof,)))


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Aff2(MatrixGroup):
    """Orientation-preserving affine maps of the plane, ``p ↦ A p + t`` with det A > 0.

    Tangent (x, y, θ, σ, stretch, shear): translation, rotation, uniform log-scale, and the two
    traceless symmetric directions diag(1, −1) and [[0, 1], [1, 0]] (Dellaert 2016, §8).
    """

    dof: ClassVar[int] = 6
    matrix_size: ClassVar[int] = 3
    point_dim: ClassVar[int] = 2

    @classmethod
    def generators(cls) -> np.ndarray:
        return np.stack(
            [
                _unit(3, 0, 2),
                _unit(3, 1, 2),
                _unit(3, 1, 0) - _unit(3, 0, 1),
                _unit(3, 0, 0) + _unit(3, 1, 1),
                _unit(3, 0, 0) - _unit(3, 1, 1),
                _unit(3, 0, 1) + _unit(3, 1, 0),
            ]
        )

    def normalize(self) -> Aff2:
        """Scale so that the last row is (0, 0, 1)."""
        m = self.matrix / self.matrix[..., 2:, 2:]
        m = m.copy()
        m[..., 2, :2] = 0.0
        return Aff2(m)


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class SL3(MatrixGroup):
    """3×3 matrices of determinant 1: homographies of the plane (Dellaert 2016, §9).

    Tangent order, the sl(3) basis of Mei et al. (2008): translations E13, E23; rotation
    E21 − E12; scale E11 + E22 − 2 E33; stretch E11 − E22; shear E12 + E21; projective E31, E32.
    ``act`` is the linear action on homogeneous 3-vectors.
    """

    dof: ClassVar[int] = 8
    matrix_size: ClassVar[int] = 3
    point_dim: ClassVar[int] = 3

    @classmethod
    def generators(cls) -> np.ndarray:
        return np.stack(
            [
                _unit(3, 0, 2),
                _unit(3, 1, 2),
                _unit(3, 1, 0) - _unit(3, 0, 1),
                _unit(3, 0, 0) + _unit(3, 1, 1) - 2.0 * _unit(3, 2, 2),
                _unit(3, 0, 0) - _unit(3, 1, 1),
                _unit(3, 0, 1) + _unit(3, 1, 0),
                _unit(3, 2, 0),
                _unit(3, 2, 1),
            ]
        )

    def normalize(self) -> SL3:
        """Divide by the cube root of the determinant."""
        return SL3(self.matrix / np.cbrt(np.linalg.det(self.matrix))[..., None, None])
