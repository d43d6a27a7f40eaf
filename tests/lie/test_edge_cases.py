"""Hand-picked numerically hard cases per group, in the style of Sophus's tests."""

from __future__ import annotations

import functools
import subprocess
import sys
import warnings
from decimal import Decimal, localcontext
from math import factorial

import numpy as np
import pytest
import scipy.linalg

from posegraph.lie import SE2, SE3, SO2, SO3, LieGroup, Sim3
from posegraph.lie._coeffs import (
    half_cot_half,
    rotation_coefficients,
    se3_q_coefficients,
    so3_jr_inv_coefficient,
)
from posegraph.lie.base import integral_of_exp
from posegraph.lie.sim3 import _moments, w_derivatives
from posegraph.lie.so3 import project_to_rotation

from ..helpers import assert_same_element, numerical_jacobian

# Either side of the coefficients' switches to series, at θ = 0.1, 0.5 and 1 (Sim3), too.
ANGLES = [0.0, 1e-8, 1e-4, 0.099, 0.101, 0.499, 0.501, 0.999, 1.001, np.pi - 1e-6, np.pi]
LOG_SCALES = [0.0, 1e-8, -1e-8, 3.0, -3.0, 9.0, -9.0, 25.0, -25.0]  # |σ| ≥ 20: by recurrence
AXIS = np.array([0.48, -0.6, 0.64])  # unit length


def _tangent(group: type[LieGroup], angle: float, log_scale: float = 0.0) -> np.ndarray:
    if group is SO2:
        return np.array([angle])
    if group is SE2:
        return np.array([0.7, -0.3, angle])
    if group is SO3:
        return angle * AXIS
    if group is SE3:
        return np.concatenate([[0.7, -0.3, 0.2], angle * AXIS])
    return np.concatenate([[0.7, -0.3, 0.2], angle * AXIS, [log_scale]])


CASES = [(g, a, 0.0) for g in (SO2, SE2, SO3, SE3) for a in ANGLES] + [
    (Sim3, a, s) for a in ANGLES for s in LOG_SCALES
]
IDS = [f"{g.__name__}-theta={a:g}-sigma={s:g}" for g, a, s in CASES]


@pytest.mark.parametrize("group, angle, log_scale", CASES, ids=IDS)
def test_exp_log_at_hard_angles(group, angle, log_scale):
    tangent = _tangent(group, angle, log_scale)
    x = group.exp(tangent)
    np.testing.assert_allclose(
        x.as_matrix(), scipy.linalg.expm(group.hat(tangent)), rtol=1e-10, atol=1e-12
    )
    recovered = x.log()
    assert_same_element(group.exp(recovered), x, atol=1e-12 * np.exp(abs(log_scale)))
    if angle < np.pi:
        np.testing.assert_allclose(recovered, tangent, rtol=1e-9, atol=1e-12)
    else:  # At θ = π, +φ and −φ are the same rotation; the rest of ξ is recovered either way.
        rotation_part = {SO2: [0], SE2: [2], SO3: [0, 1, 2], SE3: [3, 4, 5], Sim3: [3, 4, 5]}[group]
        assert np.isclose(np.linalg.norm(recovered[rotation_part]), np.pi, atol=1e-12)


@pytest.mark.parametrize("group, angle, log_scale", CASES, ids=IDS)
def test_jacobians_at_hard_angles(group, angle, log_scale):
    tangent = _tangent(group, angle, log_scale)
    exact = LieGroup.jr.__func__(group, tangent)  # the exact integral, no small-angle branch
    np.testing.assert_allclose(group.jr(tangent), exact, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        group.jr_inv(tangent) @ group.jr(tangent), np.eye(group.dof), atol=1e-9
    )
    numeric = numerical_jacobian(
        group.exp, tangent, group.dof, input_on_group=False, output_on_group=True
    )
    # Central differences (step 1e-6) round to about 1e-10 of the largest entry, which reaches
    # e²⁵ at σ = −25: 1e-6, or 1e-9 of that entry where it is larger.
    np.testing.assert_allclose(
        group.jr(tangent), numeric, atol=max(1e-6, 1e-9 * np.abs(exact).max())
    )


@pytest.mark.parametrize("angle", [1e-8, 1e-4, 0.3, np.pi - 1e-6])
def test_rotation_log_is_accurate(angle):
    """Log recovers θ to full relative precision across the range, including near π."""
    phi = SO3.exp(angle * AXIS).log()
    np.testing.assert_allclose(np.linalg.norm(phi), angle, rtol=1e-12)
    np.testing.assert_allclose(phi / np.linalg.norm(phi), AXIS, atol=1e-9)


def test_log_of_half_turn_conjugated():
    """A half-turn about an arbitrary axis (Sophus: π 'conjugated'): X·Exp(π e_z)·X⁻¹."""
    rng = np.random.default_rng(3)
    x = SO3.sample(rng, (50,))
    half_turn = SO3.exp(np.array([0.0, 0.0, np.pi]))
    conjugated = x @ half_turn @ x.inverse()
    phi = conjugated.log()
    np.testing.assert_allclose(np.linalg.norm(phi, axis=-1), np.pi, atol=1e-12)
    assert_same_element(SO3.exp(phi), conjugated, atol=1e-12)


def test_quaternions_with_negative_w():
    rng = np.random.default_rng(4)
    q = rng.normal(size=(100, 4))
    q[:, 3] = -np.abs(q[:, 3])
    r = SO3.from_quaternion(q)
    assert_same_element(r, SO3.from_quaternion(-q), atol=1e-14)
    back = r.as_quaternion()
    assert np.all(back[:, 3] >= 0)
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    np.testing.assert_allclose(back, -unit, atol=1e-12)


@pytest.mark.parametrize(
    "q", [[1, 0, 0, 0], [0, 0, 1, 0], [0.6, 0.8, 0, 0], [0, 0, 0, -1], [0, 0.6, 0, -1e-9]]
)
def test_quaternion_round_trip_near_w_zero_and_minus_one(q):
    q = np.asarray(q, float)
    r = SO3.from_quaternion(q)
    back = r.as_quaternion()
    unit = q / np.linalg.norm(q)
    assert np.allclose(back, unit, atol=1e-12) or np.allclose(back, -unit, atol=1e-12)
    assert_same_element(SO3.from_quaternion(back), r, atol=1e-14)


def test_pose_quaternion_conversions():
    rng = np.random.default_rng(5)
    x = SE3.sample(rng, (10,))
    q, t = x.as_quaternion_translation()
    assert_same_element(SE3.from_quaternion_translation(q, t), x, atol=1e-13)
    s = Sim3.sample(rng, (10,))
    assert_same_element(
        Sim3.from_quaternion_translation_scale(s.as_quaternion(), s.translation, s.scale), s, 1e-13
    )


def test_angles_wrap():
    assert np.isclose(SO2(3.0).compose(SO2(1.0)).angle, 4.0 - 2 * np.pi)
    assert SO2.exp(np.array([np.pi])).angle == np.pi
    assert SO2.exp(np.array([-np.pi])).angle == np.pi
    np.testing.assert_allclose(
        SE2.from_xytheta([1.0, 2.0, 7.0]).as_xytheta(), [1, 2, 7 - 2 * np.pi]
    )


def test_angles_in_range_are_kept_bit_for_bit():
    angles = np.array([1e-10, -0.00818381, 3.0, -3.0, np.pi, np.nextafter(-np.pi, 0.0)])
    assert np.array_equal(SO2(angles).normalize().angle, angles)
    assert np.array_equal(SE2.from_xytheta(np.c_[angles, angles, angles]).angle, angles)


def test_normalize_projects_drifted_rotations():
    rng = np.random.default_rng(6)
    x = SE3.sample(rng, (20,))
    drifted = SE3(x.rotation + 1e-6 * rng.normal(size=x.rotation.shape), x.translation)
    fixed = drifted.normalize()
    np.testing.assert_allclose(
        fixed.rotation @ np.swapaxes(fixed.rotation, -1, -2),
        np.broadcast_to(np.eye(3), (20, 3, 3)),
        atol=1e-14,
    )
    np.testing.assert_allclose(np.linalg.det(fixed.rotation), 1.0, atol=1e-14)
    assert_same_element(fixed, x, atol=1e-5)


def test_projecting_a_matrix_that_holds_an_infinity_returns():
    """numpy 2.4's SVD (OpenBLAS's LAPACK) never returns on a matrix that holds ±∞. The
    projection skips such matrices: NaN for them and for NaN ones, the same rotation as
    ``np.linalg.svd`` gives for the others. In a child process, so that a regression fails
    after 60 s instead of hanging the suite."""
    code = """
import numpy as np
from posegraph.lie.so3 import project_to_rotation, svd_of_finite
matrices = np.random.default_rng(8).normal(size=(4, 3, 3))
matrices[1, 0, 2], matrices[3, 1, 1] = np.inf, np.nan
projected = project_to_rotation(matrices)
assert np.isnan(projected[[1, 3]]).all()
alone = project_to_rotation(matrices[[0, 2]])
assert np.array_equal(projected[[0, 2]], alone)
u, singular, vt = svd_of_finite(matrices[[0, 2]])
assert np.allclose(u * singular[:, None, :] @ vt, matrices[[0, 2]], atol=1e-12)
"""
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_project_to_rotation_2d_is_the_nearest_rotation():
    """The closed form for 2 × 2 matrices against a search over a fine grid of angles: no
    rotation on the grid is nearer in Frobenius norm, and the nearest one on the grid is within
    the grid's spacing. Cases include a reflection and a matrix of determinant near 0."""
    rng = np.random.default_rng(7)
    matrices = np.concatenate(
        [rng.normal(size=(50, 2, 2)), [[[1.0, 0.0], [0.0, -1.0]], [[1.0, 2.0], [0.5, 1.0]]]]
    )
    projected = project_to_rotation(matrices)
    np.testing.assert_allclose(
        projected @ np.swapaxes(projected, 1, 2),
        np.broadcast_to(np.eye(2), matrices.shape),
        atol=1e-14,
    )
    np.testing.assert_allclose(np.linalg.det(projected), 1.0, atol=1e-14)
    grid = np.linspace(-np.pi, np.pi, 20001)
    candidates = np.stack(
        [np.stack([np.cos(grid), -np.sin(grid)], -1), np.stack([np.sin(grid), np.cos(grid)], -1)],
        -2,
    )
    for matrix, rotation in zip(matrices, projected, strict=True):
        distances = np.linalg.norm(candidates - matrix, axis=(1, 2))
        assert np.linalg.norm(rotation - matrix) <= distances.min() + 1e-12
        nearest = candidates[np.argmin(distances)]
        assert np.linalg.norm(rotation - nearest) < 2 * (grid[1] - grid[0]) or np.allclose(
            distances, distances[0]
        )


def test_sim3_from_general_homogeneous_matrix():
    """A 4×4 with last row (0, 0, 0, w) (Eade's form, w = 1/s) is normalised on read."""
    s = Sim3.sample(np.random.default_rng(7))
    eade = s.as_matrix() / s.scale
    assert_same_element(Sim3.from_matrix(eade), s, atol=1e-13)


@pytest.mark.parametrize("log_scale", [-250.0, 250.0])
def test_sim3_from_matrix_takes_scales_whose_cube_is_beyond_double_precision(log_scale):
    """det(sR) = s³ of e^±750 over- or underflows; the scale is still recovered, silently."""
    s = Sim3(
        SO3.exp(np.array([0.3, -0.2, 0.1])).rotation, np.array([1.0, 2.0, 3.0]), np.exp(log_scale)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = Sim3.from_matrix(s.as_matrix())
    assert np.log(back.scale) == pytest.approx(log_scale, rel=1e-14)
    np.testing.assert_allclose(back.rotation, s.rotation, atol=1e-14)


DIGITS = 700  # m_k(σ) by parts loses about k·|log₁₀ σ| digits to cancellation


@functools.cache
def _exact_moments(sigma: float, count: int) -> tuple[Decimal, ...]:
    """m_k(σ) = ∫₀¹ e^{σu} uᵏ du for k < count, integrated by parts in ``DIGITS`` digits:
    e^σ Σ_{j≤k} (−1)ʲ k!/((k − j)! σ^{j+1}) − (−1)ᵏ k!/σ^{k+1} (1/(k + 1) at σ = 0)."""
    with localcontext() as context:
        context.prec = DIGITS
        s = Decimal(sigma)
        if s == 0:
            return tuple(Decimal(1) / (k + 1) for k in range(count))
        e = s.exp()
        return tuple(
            e
            * sum(
                (-1) ** j * Decimal(factorial(k) // factorial(k - j)) / s ** (j + 1)
                for j in range(k + 1)
            )
            - (-1) ** k * Decimal(factorial(k)) / s ** (k + 1)
            for k in range(count)
        )


@pytest.mark.parametrize(
    "sigma", [-40.0, -20.0, -19.99, -7.9, -0.5, -1e-7, 0.0, 1e-7, 2.0, 7.9, 19.99, 20.0, 40.0]
)
def test_sim3_moments_match_exact_references(sigma):
    """Every moment Sim3's series use, by its own series (Kummer's form for σ < 0) below
    |σ| = 20 and by recurrence above, to 2e-15 relative."""
    exact = np.array([float(m) for m in _exact_moments(sigma, 25)])
    np.testing.assert_allclose(_moments(np.array([sigma]), 24)[:, 0], exact, rtol=2e-15, atol=0)


@pytest.mark.parametrize("sigma", [-7.9, -1.0, 0.0, 1e-7, 2.5, 7.9, 25.0])
@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.3, 0.999, 1.001, 2.0, np.pi - 1e-6])
def test_sim3_w_coefficients_and_derivatives_match_exact_references(sigma, angle):
    """a, b, c of W and their derivatives (``w_derivatives``) against their series in θ² summed
    in ``DIGITS`` digits on exact moments: to 3e-15 relative below θ = 1 (series), and 1e-13
    above (closed forms, which lose up to two digits in (∂c/∂θ)/θ for σ < 0)."""
    moments = _exact_moments(sigma, 60)
    with localcontext() as context:
        context.prec = DIGITS
        t2 = Decimal(angle) ** 2

        def series(first: int, weight) -> float:
            powers = [t2**j if j else Decimal(1) for j in range(28)]  # Decimal refuses 0⁰
            return float(sum(weight(j) * powers[j] * moments[first + 2 * j] for j in range(28)))

        def alternating(offset: int):
            return lambda j: Decimal((-1) ** j) / factorial(2 * j + offset)

        def derivative(offset: int):
            return lambda j: Decimal((-1) ** (j + 1) * 2 * (j + 1)) / factorial(2 * j + 2 + offset)

        exact = [
            float(moments[0]),
            series(1, alternating(1)),
            series(2, alternating(2)),
            float(moments[1]),
            series(2, alternating(1)),
            series(3, alternating(2)),
            series(3, derivative(1)),
            series(4, derivative(2)),
        ]
    computed = [value.item() for value in w_derivatives(sigma, angle)]
    np.testing.assert_allclose(computed, exact, rtol=3e-15 if angle < 1.0 else 1e-13, atol=0)


def test_sim3_series_take_the_terms_the_largest_value_of_the_batch_needs():
    """W's series take as many terms in θ² and σ as the batch's largest θ and |σ| need: each
    element of a mixed batch equals the element evaluated alone (with its own, fewer terms)."""
    sigma = np.array([1e-9, -0.3, 0.02, -7.9, 5.0, 19.0])
    theta = np.array([0.95, 1e-9, 0.01, 0.2, 1e-4, 0.6])
    batch = np.array(w_derivatives(sigma, theta))
    alone = np.array([w_derivatives(s, t) for s, t in zip(sigma, theta, strict=True)]).T
    np.testing.assert_allclose(batch, alone, rtol=1e-15, atol=0)


def _exact_trig(angle: float, digits: int = 60) -> tuple[Decimal, Decimal, Decimal]:
    """θ, sin θ and cos θ in ``digits`` digits, by their Taylor series."""
    with localcontext() as context:
        context.prec = digits
        t = Decimal(angle)
        sin = sum((-1) ** k * t ** (2 * k + 1) / factorial(2 * k + 1) for k in range(60))
        cos = sum((-1) ** k * t ** (2 * k) / factorial(2 * k) for k in range(60))
        return t, sin, cos


def _exact_coefficients(angle: float) -> list[float]:
    """The closed forms of ``_coeffs``' coefficients in 60 digits, where none cancels: those
    of ``rotation_coefficients``, ``se3_q_coefficients``, ``so3_jr_inv_coefficient`` and
    ``half_cot_half``."""
    t, sin, cos = _exact_trig(angle)
    with localcontext() as context:
        context.prec = 60
        return [
            float(value)
            for value in (
                sin / t,
                (1 - cos) / t**2,
                (t - sin) / t**3,
                (t - sin) / t**3,
                (t**2 + 2 * cos - 2) / (2 * t**4),
                (2 * t - 3 * sin + t * cos) / (2 * t**5),
                (1 - t * sin / (2 * (1 - cos))) / t**2,
                t * sin / (2 * (1 - cos)),
            )
        ]


def _coefficients(angle: np.ndarray) -> np.ndarray:
    """The same from ``_coeffs``, (8, …): the Q coefficients repeat (θ − sin θ)/θ³."""
    return np.array(
        [
            *rotation_coefficients(angle),
            *se3_q_coefficients(angle),
            so3_jr_inv_coefficient(angle),
            half_cot_half(angle),
        ]
    )


@pytest.mark.parametrize("angle", [1e-8, 1e-4, 0.05, 0.099, 0.101, 0.3, 0.499, 0.501, 1.0, 3.0])
def test_rotation_coefficients_match_exact_references(angle):
    """The SO(3)/SE(3) coefficients and SE(2)'s (θ/2) cot(θ/2) against their closed forms in 60
    digits: to 3e-15 relative where a series sums them (θ < 0.1, the Q coefficients θ < 0.5),
    and 1e-11 where a closed form cancels just above its switch (jr⁻¹'s φ×² coefficient at
    θ = 0.101: 7.6e-12, on a term θ² times smaller than the identity it is added to)."""
    exact = np.array(_exact_coefficients(angle))
    computed = _coefficients(np.array(angle))
    series = np.array([angle < 0.1] * 3 + [angle < 0.5] * 3 + [angle < 0.1] * 2)
    tolerance = np.where(series, 3e-15, 1e-11)
    assert np.all(np.abs(computed - exact) <= tolerance * np.abs(exact))


def test_rotation_series_take_the_terms_the_largest_angle_of_the_batch_needs():
    """A batch of angles below the switches sums as many terms as its largest needs: each
    element equals the element evaluated alone (with its own, fewer terms)."""
    angles = np.array([1e-9, 0.09, 1e-4, 0.02, 0.0])
    alone = np.array([_coefficients(np.array(a)) for a in angles]).T
    np.testing.assert_allclose(_coefficients(angles), alone, rtol=1e-15, atol=0)


def test_integral_of_exp_matches_van_loans_block_exponential():
    """φ₁(A) = ∫₀¹ exp(sA) ds, scaled per matrix in one batch (‖A‖₁ from 0 to ≈ 400), against
    the upper-right block of expm([[A, I], [0, 0]]) (Van Loan 1978) through scipy."""
    rng = np.random.default_rng(11)
    a = rng.normal(size=(6, 5, 5)) * np.array([0.0, 1e-9, 0.1, 1.0, 10.0, 80.0])[:, None, None]
    block = np.zeros((6, 10, 10))
    block[:, :5, :5], block[:, :5, 5:] = a, np.eye(5)
    reference = scipy.linalg.expm(block)[:, :5, 5:]
    scale = np.abs(reference).max(axis=(1, 2), keepdims=True)
    np.testing.assert_allclose(integral_of_exp(a) / scale, reference / scale, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(integral_of_exp(np.zeros((3, 3))), np.eye(3))
    with np.errstate(invalid="ignore"):  # inf · 0 in the products
        assert not np.isfinite(integral_of_exp(np.full((2, 2), np.inf))).any()


@pytest.mark.parametrize("norm", [1e-9, 1e-3, 0.05, 0.3])
def test_integral_of_exp_sums_as_many_terms_as_the_largest_matrix_of_the_batch_needs(norm):
    """A batch of small matrices takes fewer Taylor terms than one with a large matrix in it
    (which is scaled, and sets the most terms): the two agree to rounding, and both agree with
    Van Loan's block exponential."""
    rng = np.random.default_rng(12)
    small = rng.normal(size=(5, 7, 7))
    small *= norm / np.abs(small).sum(axis=1).max(axis=1)[:, None, None]
    large = 40.0 * rng.normal(size=(1, 7, 7))
    alone, mixed = integral_of_exp(small), integral_of_exp(np.concatenate([small, large]))[:5]
    np.testing.assert_allclose(alone, mixed, rtol=0, atol=4e-16)
    block = np.zeros((5, 14, 14))
    block[:, :7, :7], block[:, :7, 7:] = small, np.eye(7)
    np.testing.assert_allclose(alone, scipy.linalg.expm(block)[:, :7, 7:], rtol=0, atol=1e-14)
