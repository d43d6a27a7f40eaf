"""Small-angle-safe series coefficients and the so(3)/so(2) hat and vee maps.

Every coefficient ``f(θ)`` below is an even function of θ. Each is evaluated in closed form away
from zero and by its Taylor series in θ² below ``_SERIES_BELOW``, where the closed form loses
digits to cancellation. The series are truncated where the next term is below 1e-17 relative.
Formulas: Eade, "Lie Groups for 2D and 3D Transformations", §2.2–§3.2, and Barfoot,
"State Estimation for Robotics", §7.1.5 (the SE(3) Q-matrix coefficients).
"""

from __future__ import annotations

from collections.abc import Callable
from math import factorial

import numpy as np

_SERIES_BELOW = 0.1
# The Q-matrix coefficients cancel to the fifth order: their series take over further out.
_Q_SERIES_BELOW = 0.5


def series_terms(first_left_out: Callable[[int], float], below: float, most: int) -> int:
    """The fewest terms n < ``most`` of a truncated series whose first term left out,
    ``first_left_out(n)``, is below ``below``; ``most`` if none is."""
    return next((n for n in range(most) if first_left_out(n) < below), most)


def powers(x: np.ndarray, count: int) -> np.ndarray:
    """(count, …) array of xⁿ, n < count."""
    out = np.empty((count,) + x.shape)
    out[0] = 1.0
    for n in range(1, count):  # faster than np.cumprod along the first axis
        np.multiply(out[n - 1], x, out=out[n])
    return out


class EvenSeries:
    """Σ_k c_k θ^{2k} for coefficients (k,), or for each column of (k, n) at once, summed up to
    the first term below 1e-17 of the leading one at the largest θ² given (θ² < 0.25 where a
    series is used, and the terms fall fast)."""

    def __init__(self, coefficients) -> None:
        self.coefficients = np.asarray(coefficients, dtype=float)
        ratios = np.abs(self.coefficients / self.coefficients[0])
        self._ratios = ratios.reshape(len(ratios), -1).max(axis=1).tolist()

    def __call__(self, theta_sq: np.ndarray) -> np.ndarray:
        """The sums, shaped as θ² for coefficients (k,), as (n, …) for (k, n)."""
        theta_sq = np.asarray(theta_sq, dtype=float)
        largest, ratios = float(theta_sq.max(initial=0.0)), self._ratios
        terms = series_terms(lambda k: ratios[k] * largest**k, 1e-17, len(ratios))
        sums = self.coefficients[:terms].T @ powers(theta_sq.reshape(-1), terms)
        return sums.reshape(self.coefficients.shape[1:] + theta_sq.shape)


def _coefficients(
    theta: np.ndarray, closed_forms, series: EvenSeries, below: float = _SERIES_BELOW
) -> tuple[np.ndarray, ...]:
    """n coefficients of θ: ``closed_forms(θ)`` returns them as a tuple (sharing one sin and
    cos), and column k of ``series`` (terms, n) is the even series of the k-th, used where
    |θ| < ``below``. The closed forms never see those θ, so they may divide by θ."""
    theta = np.asarray(theta, dtype=float)
    small = np.abs(theta) < below
    if not small.any():
        return closed_forms(theta)
    if small.all():
        return tuple(series(theta * theta))
    coefficients = tuple(np.asarray(c) for c in closed_forms(np.where(small, 1.0, theta)))
    theta_sq = theta[small] ** 2
    for values, out in zip(series(theta_sq), coefficients, strict=True):
        out[small] = values
    return coefficients


def _coefficient(
    theta: np.ndarray, closed_form, series: EvenSeries, below: float = _SERIES_BELOW
) -> np.ndarray:
    """One coefficient: ``_coefficients`` with a single closed form and series (terms, 1)."""
    return _coefficients(theta, lambda t: (closed_form(t),), series, below)[0]


def _alternating(offset: int, terms: int = 8) -> list[float]:
    """Coefficients (-1)^k / (2k + offset)!: the Taylor series of sin and cos remainders."""
    return [(-1.0) ** k / factorial(2 * k + offset) for k in range(terms)]


_ROTATION_SERIES = EvenSeries(np.array([_alternating(1), _alternating(2), _alternating(3)]).T)
"""Series of sin θ/θ, (1 − cos θ)/θ² and (θ − sin θ)/θ³, one per column."""


def rotation_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sin θ/θ, (1 − cos θ)/θ², (θ − sin θ)/θ³) from one sin and cos evaluation, with their
    series below ``_SERIES_BELOW``."""

    def closed_forms(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        inverse = 1.0 / t
        inverse_sq = inverse * inverse
        a = np.sin(t) * inverse
        return a, (1.0 - np.cos(t)) * inverse_sq, (1.0 - a) * inverse_sq

    return _coefficients(theta, closed_forms, _ROTATION_SERIES)


_Q_SERIES = EvenSeries(
    np.array(
        [
            _alternating(3, terms=10),
            _alternating(4, terms=10),
            [(-1.0) ** k * (k + 1) / factorial(2 * k + 5) for k in range(10)],
        ]
    ).T
)
"""The three coefficients' series, one per column."""


def se3_q_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three Q-matrix coefficients of Barfoot eq. 7.86, from one sin and cos evaluation:
    (θ − sin θ)/θ³, (θ² + 2 cos θ − 2)/(2 θ⁴) and (2θ − 3 sin θ + θ cos θ)/(2 θ⁵); their series
    below ``_Q_SERIES_BELOW``."""

    def closed_forms(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sin, cos, t_sq = np.sin(t), np.cos(t), t * t
        return (
            (t - sin) / (t_sq * t),
            (t_sq + 2.0 * cos - 2.0) / (2.0 * t_sq * t_sq),
            (2.0 * t - 3.0 * sin + t * cos) / (2.0 * t_sq * t_sq * t),
        )

    return _coefficients(theta, closed_forms, _Q_SERIES, _Q_SERIES_BELOW)


_JR_INV_TERMS = [1 / 12, 1 / 720, 1 / 30240, 1 / 1209600, 1 / 47900160]
_JR_INV_SERIES = EvenSeries(_JR_INV_TERMS)
"""Series of (1 − (θ/2) cot(θ/2))/θ², from x cot x = 1 − Σ 2^{2n} |B_{2n}| x^{2n} / (2n)!."""


def so3_jr_inv_coefficient(theta: np.ndarray) -> np.ndarray:
    """(1 − (θ/2) cot(θ/2)) / θ², the φ×² coefficient of the inverse SO(3) Jacobian."""
    theta = np.asarray(theta, dtype=float)
    return so3_jr_inv_coefficient_from_trig(theta, np.sin(theta), np.cos(theta))


def so3_jr_inv_coefficient_from_trig(
    theta: np.ndarray, sin: np.ndarray, cos: np.ndarray
) -> np.ndarray:
    """The same, given sin θ and cos θ (a logarithm has them before it has θ)."""
    small = np.abs(theta) < _SERIES_BELOW
    if not small.any():
        return (1.0 - 0.5 * theta * sin / (1.0 - cos)) / theta**2
    if small.all():
        return _JR_INV_SERIES(theta * theta)
    safe = np.where(small, 1.0, theta)
    result = np.asarray(
        (1.0 - 0.5 * safe * np.where(small, 0.0, sin) / np.where(small, 1.0, 1.0 - cos)) / safe**2
    )
    result[small] = _JR_INV_SERIES(theta[small] ** 2)
    return result


_HALF_COT_SERIES = EvenSeries(np.array([1.0, *(-c for c in _JR_INV_TERMS)])[:, None])


def half_cot_half(theta: np.ndarray) -> np.ndarray:
    """(θ/2) cot(θ/2) = θ sin θ / (2 (1 − cos θ)), used by the SE(2) logarithm. Its series is
    1 − θ² times that of ``so3_jr_inv_coefficient``."""
    return _coefficient(theta, lambda t: 0.5 * t * np.sin(t) / (1.0 - np.cos(t)), _HALF_COT_SERIES)


def hat3(v: np.ndarray) -> np.ndarray:
    """The skew-symmetric matrix v× of a (…, 3) array, so that (v×) p = v × p."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    np.negative(v[..., 2], out=out[..., 0, 1])
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    np.negative(v[..., 0], out=out[..., 1, 2])
    np.negative(v[..., 1], out=out[..., 2, 0])
    out[..., 2, 1] = v[..., 0]
    return out


def _components(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contiguous x, y, z of a (…, 3) array (elementwise work on strided columns is slower)."""
    phi = np.asarray(phi, dtype=float)
    return np.array(phi[..., 0]), np.array(phi[..., 1]), np.array(phi[..., 2])  # copies keep 0-d


def so3_polynomial(phi: np.ndarray, c0, c1, c2) -> np.ndarray:
    """c0 I + c1 φ× + c2 φ×² as (…, 3, 3), written entrywise with φ×² = φφᵀ − |φ|² I.

    Exp, the Jacobians and V of SO(3), SE(3) and Sim(3) are all of this form.
    """
    x, y, z = _components(phi)
    c0, c1, c2 = np.asarray(c0, float), np.asarray(c1, float), np.asarray(c2, float)
    shape = np.broadcast_shapes(x.shape, c0.shape, c1.shape, c2.shape)
    c2x, c2y, c2z = c2 * x, c2 * y, c2 * z
    c1x, c1y, c1z = c1 * x, c1 * y, c1 * z
    diagonal = c0 - (c2x * x + c2y * y + c2z * z)
    xy, xz, yz = c2x * y, c2x * z, c2y * z
    out = np.empty(shape + (3, 3))
    np.multiply(c2x, x, out=out[..., 0, 0])
    out[..., 0, 0] += diagonal
    np.multiply(c2y, y, out=out[..., 1, 1])
    out[..., 1, 1] += diagonal
    np.multiply(c2z, z, out=out[..., 2, 2])
    out[..., 2, 2] += diagonal
    np.subtract(xy, c1z, out=out[..., 0, 1])
    np.add(xy, c1z, out=out[..., 1, 0])
    np.add(xz, c1y, out=out[..., 0, 2])
    np.subtract(xz, c1y, out=out[..., 2, 0])
    np.subtract(yz, c1x, out=out[..., 1, 2])
    np.add(yz, c1x, out=out[..., 2, 1])
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (faster than ``np.cross`` on small trailing axes)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = ay * bz - az * by
    out[..., 1] = az * bx - ax * bz
    out[..., 2] = ax * by - ay * bx
    return out


def so3_polynomial_apply(phi: np.ndarray, c0, c1, c2, v: np.ndarray) -> np.ndarray:
    """(c0 I + c1 φ× + c2 φ×²) v without forming the matrix: c0 v + c1 (φ × v) + c2 φ × (φ × v),
    with φ × (φ × v) = φ (φ·v) − |φ|² v. Works in place on one scratch buffer (this is on the
    path of every exp and log)."""
    x, y, z = _components(phi)
    vx, vy, vz = _components(v)
    c0, c1, c2 = np.asarray(c0, float), np.asarray(c1, float), np.asarray(c2, float)
    scale_phi = c2 * (x * vx + y * vy + z * vz)
    scale_v = c0 - c2 * (x * x + y * y + z * z)
    out = np.empty(np.broadcast_shapes(x.shape, vx.shape, c0.shape, c1.shape, c2.shape) + (3,))
    scratch = np.empty(out.shape[:-1])
    for k, (a, b, c, d, v_k, phi_k) in enumerate(
        ((y, vz, z, vy, vx, x), (z, vx, x, vz, vy, y), (x, vy, y, vx, vz, z))
    ):
        np.multiply(a, b, out=scratch)
        scratch -= c * d  # (φ × v)_k
        scratch *= c1
        scratch += scale_v * v_k
        scratch += scale_phi * phi_k
        out[..., k] = scratch
    return out


def vee3(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat3`, reading the skew part of a (…, 3, 3) array."""
    out = np.empty(m.shape[:-2] + (3,))
    np.subtract(m[..., 2, 1], m[..., 1, 2], out=out[..., 0])
    np.subtract(m[..., 0, 2], m[..., 2, 0], out=out[..., 1])
    np.subtract(m[..., 1, 0], m[..., 0, 1], out=out[..., 2])
    return 0.5 * out


def wrap_angle(theta: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π], as a new array. Angles already there are returned bit for bit:
    the shift by π would round them (1e-10 + π − π = 1.00000008e-10), and a file's angles would
    be written back with other digits."""
    theta = np.array(theta, dtype=float)
    if np.abs(theta).max(initial=0.0) < np.pi:  # False for NaN: those are wrapped (to NaN)
        return theta
    outside = ~((theta > -np.pi) & (theta <= np.pi))
    wrapped = np.remainder(theta[outside] + np.pi, 2.0 * np.pi) - np.pi
    theta[outside] = np.where(wrapped == -np.pi, np.pi, wrapped)
    return theta
