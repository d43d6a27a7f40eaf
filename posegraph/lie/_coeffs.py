"""Small-angle-safe series coefficients and the so(3)/so(2) hat and vee maps.

Every coefficient ``f(θ)`` below is an even function of θ. Each is evaluated in closed form away
from zero and by its Taylor series in θ² below ``_SERIES_BELOW``, where the closed form loses
digits to cancellation. The series are truncated where the next term is below 1e-17 relative.
Formulas: Eade, "Lie Groups for 2D and 3D Transformations", §2.2–§3.2, and Barfoot,
"State Estimation for Robotics", §7.1.5 (the SE(3) Q-matrix coefficients).
"""

from __future__ import annotations

from math import factorial

import numpy as np

_SERIES_BELOW = 0.1
# The Q-matrix coefficients cancel to the fifth order: their series take over further out.
_Q_SERIES_BELOW = 0.5


def _even_series(theta_sq: np.ndarray, coefficients: list[float]) -> np.ndarray:
    """Evaluate Σ_k c_k θ^{2k} by Horner's rule."""
    result = np.zeros_like(theta_sq)
    for c in reversed(coefficients):
        result = result * theta_sq + c
    return result


def _coefficient(
    theta: np.ndarray, closed_form, series: list[float], below: float = _SERIES_BELOW
) -> np.ndarray:
    """Pick the closed form or its series, without dividing by zero in the unused branch."""
    theta = np.asarray(theta, dtype=float)
    small = np.abs(theta) < below
    if not np.any(small):
        return closed_form(theta)
    result = np.asarray(closed_form(np.where(small, 1.0, theta)))
    result[small] = _even_series(theta[small] ** 2, series)
    return result


def _alternating(offset: int, terms: int = 8) -> list[float]:
    """Coefficients (-1)^k / (2k + offset)!: the Taylor series of sin and cos remainders."""
    return [(-1.0) ** k / factorial(2 * k + offset) for k in range(terms)]


def sin_over(theta: np.ndarray) -> np.ndarray:
    """sin θ / θ."""
    return _coefficient(theta, lambda t: np.sin(t) / t, _alternating(1))


def one_minus_cos_over_sq(theta: np.ndarray) -> np.ndarray:
    """(1 − cos θ) / θ²."""
    return _coefficient(theta, lambda t: (1.0 - np.cos(t)) / t**2, _alternating(2))


def theta_minus_sin_over_cube(theta: np.ndarray) -> np.ndarray:
    """(θ − sin θ) / θ³."""
    return _coefficient(theta, lambda t: (t - np.sin(t)) / t**3, _alternating(3))


def se3_q_second(theta: np.ndarray) -> np.ndarray:
    """(θ² + 2 cos θ − 2) / (2 θ⁴), the second Q-matrix coefficient (Barfoot eq. 7.86)."""
    return _coefficient(
        theta,
        lambda t: (t * t + 2.0 * np.cos(t) - 2.0) / (2.0 * t**4),
        _alternating(4, terms=10),
        _Q_SERIES_BELOW,
    )


def se3_q_third(theta: np.ndarray) -> np.ndarray:
    """(2θ − 3 sin θ + θ cos θ) / (2 θ⁵), the third Q-matrix coefficient (Barfoot eq. 7.86)."""
    series = [(-1.0) ** j * (j + 1) / factorial(2 * j + 5) for j in range(10)]
    return _coefficient(
        theta,
        lambda t: (2.0 * t - 3.0 * np.sin(t) + t * np.cos(t)) / (2.0 * t**5),
        series,
        _Q_SERIES_BELOW,
    )


def so3_jr_inv_coefficient(theta: np.ndarray) -> np.ndarray:
    """(1 − (θ/2) cot(θ/2)) / θ², the φ×² coefficient of the inverse SO(3) Jacobian.

    Series from x cot x = 1 − Σ 2^{2n} |B_{2n}| x^{2n} / (2n)! with x = θ/2.
    """
    series = [1 / 12, 1 / 720, 1 / 30240, 1 / 1209600, 1 / 47900160]
    return _coefficient(
        theta, lambda t: (1.0 - 0.5 * t * np.sin(t) / (1.0 - np.cos(t))) / t**2, series
    )


def half_cot_half(theta: np.ndarray) -> np.ndarray:
    """(θ/2) cot(θ/2) = θ sin θ / (2 (1 − cos θ)), used by the SE(2) logarithm."""
    series = [1.0, -1 / 12, -1 / 720, -1 / 30240, -1 / 1209600]
    return _coefficient(theta, lambda t: 0.5 * t * np.sin(t) / (1.0 - np.cos(t)), series)


def hat3(v: np.ndarray) -> np.ndarray:
    """The skew-symmetric matrix v× of a (…, 3) array, so that (v×) p = v × p."""
    return so3_polynomial(v, 0.0, 1.0, 0.0)


def so3_polynomial(phi: np.ndarray, c0, c1, c2) -> np.ndarray:
    """c0 I + c1 φ× + c2 φ×² as (…, 3, 3), written entrywise with φ×² = φφᵀ − |φ|² I.

    Exp, the Jacobians and V of SO(3), SE(3) and Sim(3) are all of this form.
    """
    phi = np.asarray(phi, dtype=float)
    x, y, z = phi[..., 0], phi[..., 1], phi[..., 2]
    c0, c1, c2 = np.asarray(c0, float), np.asarray(c1, float), np.asarray(c2, float)
    diagonal = c0 - c2 * (x * x + y * y + z * z)
    shape = np.broadcast_shapes(phi.shape[:-1], c0.shape, c1.shape, c2.shape)
    out = np.empty(shape + (3, 3))
    c2xy, c2xz, c2yz = c2 * x * y, c2 * x * z, c2 * y * z
    c1x, c1y, c1z = c1 * x, c1 * y, c1 * z
    out[..., 0, 0] = diagonal + c2 * x * x
    out[..., 1, 1] = diagonal + c2 * y * y
    out[..., 2, 2] = diagonal + c2 * z * z
    out[..., 0, 1] = c2xy - c1z
    out[..., 1, 0] = c2xy + c1z
    out[..., 0, 2] = c2xz + c1y
    out[..., 2, 0] = c2xz - c1y
    out[..., 1, 2] = c2yz - c1x
    out[..., 2, 1] = c2yz + c1x
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (faster than ``np.cross`` on small trailing axes)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def so3_polynomial_apply(phi: np.ndarray, c0, c1, c2, v: np.ndarray) -> np.ndarray:
    """(c0 I + c1 φ× + c2 φ×²) v without forming the matrix."""
    phi_v = cross(phi, v)
    c0, c1, c2 = (np.asarray(c, float)[..., None] for c in (c0, c1, c2))
    return c0 * v + c1 * phi_v + c2 * cross(phi, phi_v)


def vee3(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat3`, reading the skew part of a (…, 3, 3) array."""
    return 0.5 * np.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


def wrap_angle(theta: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π]."""
    wrapped = np.remainder(np.asarray(theta, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    return np.where(wrapped == -np.pi, np.pi, wrapped)
