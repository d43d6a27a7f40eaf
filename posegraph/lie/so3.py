"""SO(3): rotations of space, stored as (…, 3, 3) matrices. Tangent (φ), the rotation vector.

Exp: Rodrigues (Eade §2.2). Log: through the unit quaternion (Shepperd's method), which stays
accurate near θ = π where the trace formula does not. Jacobians: Barfoot §7.1.3 / Eade §9.
Quaternions are ordered (qx, qy, qz, qw), as in g2o files.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from . import _coeffs
from ._coeffs import hat3, so3_polynomial, vee3
from .base import LieGroup
from .so2 import rotation_matrix_2d

# Below this cos θ (θ above ≈ 2.69) the rotation axis is read from the quaternion instead of
# the skew part of R, whose norm sin θ vanishes at π.
_NEAR_HALF_TURN_COS = -0.9


def angle(phi: np.ndarray) -> np.ndarray:
    """θ = |φ| of (…, 3) rotation vectors."""
    phi = np.asarray(phi, float)
    return np.sqrt(np.einsum("...i,...i->...", phi, phi))


def exp_matrix(phi: np.ndarray) -> np.ndarray:
    """Rodrigues: R = I + (sin θ/θ) φ× + ((1 − cos θ)/θ²) φ×²."""
    a, b, _ = _coeffs.rotation_coefficients(angle(phi))
    return so3_polynomial(phi, 1.0, a, b)


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """(…, 4) unit quaternions (x, y, z, w) with w ≥ 0, by Shepperd's largest-pivot method: the
    rows of the symmetric K = [[R + Rᵀ − (tr R − 1) I, v], [vᵀ, 1 + tr R]], v = vee(R − Rᵀ),
    are 4 q_k q for k = x, y, z, w, so the row of K's largest diagonal entry (4 q_k²) is the
    most accurate (Shepperd 1978, J. Guidance and Control 1(3))."""
    r = np.asarray(rotation, float)
    batch = r.shape[:-2]
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    k = np.empty(batch + (4, 4))
    k[..., :3, :3] = r + np.swapaxes(r, -1, -2)
    k[..., :3, 3] = k[..., 3, :3] = 2.0 * vee3(r)
    diagonal = k.reshape(-1, 16)[:, ::5]  # a view of K's diagonal
    diagonal[:, :3] -= (trace - 1.0).reshape(-1, 1)
    diagonal[:, 3] = 1.0 + trace.ravel()
    rows = k.reshape(-1, 4, 4)[np.arange(diagonal.shape[0]), np.argmax(diagonal, axis=1)]
    q = rows.reshape(batch + (4,)) / np.linalg.norm(rows, axis=-1).reshape(batch + (1,))
    return np.where(q[..., 3:] < 0, -q, q)


def quaternion_to_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrices of (…, 4) quaternions (x, y, z, w), normalised first; q ≡ −q."""
    q = np.asarray(quaternion, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def log_matrix(rotation: np.ndarray) -> np.ndarray:
    """The rotation vector φ of (…, 3, 3) rotation matrices, |φ| ≤ π (``log_with_trig``)."""
    return log_with_trig(rotation)[0]


def log_with_trig(rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(φ, θ, sin θ, cos θ) of (…, 3, 3) rotation matrices, |φ| = θ ≤ π.

    With v = vee(R − Rᵀ)/2 = sin θ · axis and cos θ = (tr R − 1)/2: θ = atan2(|v|, cos θ) and
    φ = (θ / |v|) v. Near θ = π, where |v| → 0, φ comes from the quaternion (u, w) instead:
    φ = 2 atan2(|u|, w) u / |u|.
    """
    rotation = np.asarray(rotation, float)
    v = vee3(rotation)
    cos = 0.5 * (rotation[..., 0, 0] + rotation[..., 1, 1] + rotation[..., 2, 2] - 1.0)
    sin = np.sqrt(np.einsum("...i,...i->...", v, v))
    theta = np.arctan2(sin, cos)
    tiny = sin < 1e-6
    scale = theta / np.where(tiny, 1.0, sin)
    scale = np.where(tiny, 1.0 + sin * sin / 6.0, scale)  # θ/sin θ, with θ ≈ sin θ here
    phi = scale[..., None] * v
    near_half_turn = cos < _NEAR_HALF_TURN_COS
    if np.any(near_half_turn):
        q = matrix_to_quaternion(rotation[near_half_turn])
        u, w = q[..., :3], q[..., 3]
        n = np.sqrt(np.einsum("...i,...i->...", u, u))
        phi[near_half_turn] = (2.0 * np.arctan2(n, w) / n)[..., None] * u
    return phi, theta, sin, cos


def jr_matrix(phi: np.ndarray) -> np.ndarray:
    """jr(φ) = I − ((1 − cos θ)/θ²) φ× + ((θ − sin θ)/θ³) φ×² (Barfoot eq. 7.77b)."""
    _, b, c = _coeffs.rotation_coefficients(angle(phi))
    return so3_polynomial(phi, 1.0, -b, c)


def jr_inv_matrix(phi: np.ndarray) -> np.ndarray:
    """jr⁻¹(φ) = I + ½ φ× + ((1 − (θ/2) cot(θ/2))/θ²) φ×² (Barfoot eq. 7.77b, inverted)."""
    return so3_polynomial(phi, 1.0, 0.5, _coeffs.so3_jr_inv_coefficient(angle(phi)))


def svd_of_finite(matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.linalg.svd`` (U, σ, Vᵀ) of (…, m, m) matrices, all NaN for a matrix with an entry
    that is not finite. LAPACK's SVD in numpy 2.4's OpenBLAS never returns on a matrix that
    holds ±∞ (and raises on NaN), so such matrices are not passed to it."""
    finite = np.isfinite(matrices).all(axis=(-2, -1))
    if finite.all():
        return np.linalg.svd(matrices)
    u, vt = np.full(matrices.shape, np.nan), np.full(matrices.shape, np.nan)
    singular = np.full(matrices.shape[:-1], np.nan)
    if finite.any():
        u[finite], singular[finite], vt[finite] = np.linalg.svd(matrices[finite])
    return u, singular, vt


NEARLY_ORTHONORMAL = 1e-6
"""Below this ‖MᵀM − I‖_F (and with det M > 0), ``project_to_rotation`` iterates twice in
place of an SVD: to within rounding from there."""


def project_to_rotation(matrix: np.ndarray) -> np.ndarray:
    """The nearest rotation matrix (Frobenius norm) of (…, d, d) arrays: by SVD with the
    determinant fixed to +1, or for d = 2 in closed form, θ = atan2(m₁₀ − m₀₁, m₀₀ + m₁₁),
    which maximises tr(R(θ)ᵀ M) = (m₀₀ + m₁₁) cos θ + (m₁₀ − m₀₁) sin θ. NaN where the matrix
    is not finite. A rotation off by rounding (``NEARLY_ORTHONORMAL``) takes two steps of
    X ← X (3I − XᵀX)/2, which converges quadratically to the orthogonal polar factor (Björck &
    Bowie 1971), the nearest orthogonal matrix."""
    matrix = np.asarray(matrix, float)
    if matrix.shape[-1] == 2:
        theta = np.arctan2(
            matrix[..., 1, 0] - matrix[..., 0, 1], matrix[..., 0, 0] + matrix[..., 1, 1]
        )
        return rotation_matrix_2d(theta)
    identity = np.eye(matrix.shape[-1])
    drift = np.linalg.norm(np.swapaxes(matrix, -1, -2) @ matrix - identity, axis=(-2, -1))
    if np.all(drift < NEARLY_ORTHONORMAL) and np.all(np.linalg.det(matrix) > 0):
        for _ in range(2):
            matrix = matrix @ (1.5 * identity - 0.5 * np.swapaxes(matrix, -1, -2) @ matrix)
        return matrix
    u, _, vt = svd_of_finite(matrix)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, -1] *= d[..., None]
    return u @ vt


def sample_rotation(rng: np.random.Generator, batch_shape: tuple[int, ...]) -> np.ndarray:
    """Uniformly distributed rotation matrices (normalised Gaussian quaternions)."""
    return quaternion_to_matrix(rng.normal(size=batch_shape + (4,)))


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class SO3(LieGroup):
    """Rotations ``p ↦ R p``; ``rotation`` is (…, 3, 3)."""

    rotation: np.ndarray

    dof: ClassVar[int] = 3
    matrix_size: ClassVar[int] = 3
    point_dim: ClassVar[int] = 3
    _event_ndims: ClassVar[dict[str, int]] = {"rotation": 2}

    @classmethod
    def identity(cls, batch_shape: tuple[int, ...] = ()) -> SO3:
        return cls(np.broadcast_to(np.eye(3), batch_shape + (3, 3)).copy())

    @classmethod
    def exp(cls, tangent: np.ndarray) -> SO3:
        return cls(exp_matrix(tangent))

    def log(self) -> np.ndarray:
        return log_matrix(self.rotation)

    def compose(self, other: SO3) -> SO3:
        return SO3(self.rotation @ other.rotation)

    def inverse(self) -> SO3:
        return SO3(np.swapaxes(self.rotation, -1, -2))

    def as_matrix(self) -> np.ndarray:
        return self.rotation

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> SO3:
        return cls(matrix)

    @classmethod
    def from_quaternion(cls, quaternion: np.ndarray) -> SO3:
        """From (…, 4) quaternions (x, y, z, w); normalised, and q ≡ −q."""
        return cls(quaternion_to_matrix(quaternion))

    def as_quaternion(self) -> np.ndarray:
        """(…, 4) unit quaternions (x, y, z, w) with w ≥ 0."""
        return matrix_to_quaternion(self.rotation)

    @classmethod
    def sample(cls, rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> SO3:
        return cls(sample_rotation(rng, batch_shape))

    @classmethod
    def generators(cls) -> np.ndarray:
        return hat3(np.eye(3))

    def normalize(self) -> SO3:
        return SO3(project_to_rotation(self.rotation))

    def adjoint(self) -> np.ndarray:
        """Ad_R = R."""
        return self.rotation

    @classmethod
    def ad(cls, tangent: np.ndarray) -> np.ndarray:
        return hat3(tangent)

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        return jr_matrix(tangent)

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        return jr_inv_matrix(tangent)
