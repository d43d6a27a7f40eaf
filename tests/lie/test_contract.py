"""One contract test for every group × batch shape (axioms, maps, Jacobians)."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
import scipy.linalg

from posegraph.lie import LieGroup

from ..helpers import (
    ALL_GROUPS,
    BATCH_SHAPES,
    assert_same_element,
    numerical_jacobian,
    random_tangent,
)

JACOBIAN_ATOL = 1e-7

pytestmark = pytest.mark.parametrize(
    "group, batch_shape",
    [(g, s) for g in ALL_GROUPS for s in BATCH_SHAPES],
    ids=[f"{g.__name__}-{s}" for g in ALL_GROUPS for s in BATCH_SHAPES],
)


@pytest.fixture
def rng(group, batch_shape):
    """A generator seeded by the case's name, so every run draws the same samples (``hash`` of
    a string changes from one process to the next)."""
    return np.random.default_rng(zlib.crc32(f"{group.__name__}-{batch_shape}".encode()))


def test_batch_shape_and_indexing(group, batch_shape, rng):
    x = group.sample(rng, batch_shape)
    assert x.batch_shape == batch_shape
    assert group.identity(batch_shape).batch_shape == batch_shape
    if batch_shape:
        first = x[0]
        assert first.batch_shape == batch_shape[1:]
        np.testing.assert_array_equal(first.as_matrix(), x.as_matrix()[0])
    # A single element broadcasts against a batch.
    single = group.sample(rng)
    assert (single @ x).batch_shape == batch_shape
    np.testing.assert_allclose(
        (single @ x).as_matrix(), single.as_matrix() @ x.as_matrix(), atol=1e-12
    )


def test_group_axioms(group, batch_shape, rng):
    x, y, z = (group.sample(rng, batch_shape) for _ in range(3))
    identity = group.identity(batch_shape)
    assert_same_element(x @ identity, x)
    assert_same_element(identity @ x, x)
    assert_same_element(x @ x.inverse(), identity)
    assert_same_element(x.inverse() @ x, identity)
    assert_same_element((x @ y) @ z, x @ (y @ z))


def test_exp_log_round_trips(group, batch_shape, rng):
    tangent = random_tangent(group, rng, batch_shape)
    np.testing.assert_allclose(group.exp(tangent).log(), tangent, atol=1e-10)
    x = group.sample(rng, batch_shape)
    assert_same_element(group.exp(x.log()), x)
    assert_same_element(
        group.exp(np.zeros(batch_shape + (group.dof,))), group.identity(batch_shape)
    )


def test_exp_is_the_matrix_exponential_of_hat(group, batch_shape, rng):
    tangent = random_tangent(group, rng, batch_shape)
    np.testing.assert_allclose(
        group.exp(tangent).as_matrix(), scipy.linalg.expm(group.hat(tangent)), atol=1e-12
    )
    np.testing.assert_allclose(group.vee(group.hat(tangent)), tangent, atol=1e-15)


def test_matrix_representation(group, batch_shape, rng):
    x, y = group.sample(rng, batch_shape), group.sample(rng, batch_shape)
    mx, my = x.as_matrix(), y.as_matrix()
    np.testing.assert_allclose((x @ y).as_matrix(), mx @ my, atol=1e-12)
    np.testing.assert_allclose(x.inverse().as_matrix(), np.linalg.inv(mx), atol=1e-10)
    np.testing.assert_allclose(x.between(y).as_matrix(), np.linalg.inv(mx) @ my, atol=1e-10)
    assert_same_element(group.from_matrix(mx), x, atol=1e-12)
    assert_same_element(x.normalize(), x, atol=1e-12)
    points = rng.normal(size=batch_shape + (group.point_dim,))
    lifted = points
    if group.matrix_size > group.point_dim:
        lifted = np.concatenate([points, np.ones(batch_shape + (1,))], axis=-1)
    expected = np.einsum("...ij,...j->...i", mx, lifted)[..., : group.point_dim]
    np.testing.assert_allclose(x @ points, expected, atol=1e-12)


def test_adjoint_identity(group, batch_shape, rng):
    x = group.sample(rng, batch_shape)
    delta = random_tangent(group, rng, batch_shape)
    left = x @ group.exp(delta) @ x.inverse()
    right = group.exp(np.einsum("...ij,...j->...i", x.adjoint(), delta))
    assert_same_element(left, right, atol=1e-9)


def test_small_adjoint_is_the_bracket(group, batch_shape, rng):
    xi, eta = random_tangent(group, rng, batch_shape), random_tangent(group, rng, batch_shape)
    a, b = group.hat(xi), group.hat(eta)
    bracket = group.vee(a @ b - b @ a)
    np.testing.assert_allclose(
        np.einsum("...ij,...j->...i", group.ad(xi), eta), bracket, atol=1e-12
    )
    # d/dt Ad(Exp(t ξ)) at t = 0 is ad_ξ.
    h = 1e-6
    derivative = (group.exp(h * xi).adjoint() - group.exp(-h * xi).adjoint()) / (2 * h)
    np.testing.assert_allclose(derivative, group.ad(xi), atol=1e-8)


def test_closed_forms_equal_the_generic_routines(group, batch_shape, rng):
    x = group.sample(rng, batch_shape)
    tangent = random_tangent(group, rng, batch_shape)
    np.testing.assert_allclose(x.adjoint(), LieGroup.adjoint(x), atol=1e-12)
    np.testing.assert_allclose(group.ad(tangent), LieGroup.ad.__func__(group, tangent), atol=1e-12)
    np.testing.assert_allclose(group.jr(tangent), LieGroup.jr.__func__(group, tangent), atol=1e-12)
    np.testing.assert_allclose(
        group.jr_inv(tangent), LieGroup.jr_inv.__func__(group, tangent), atol=1e-11
    )


def test_interpolation(group, batch_shape, rng):
    x, y = group.sample(rng, batch_shape), group.sample(rng, batch_shape)
    assert_same_element(x.interpolate(y, 0.0), x)
    assert_same_element(x.interpolate(y, 1.0), y, atol=1e-9)
    # The geodesic midpoint is the same walked from either end.
    assert_same_element(x.interpolate(y, 0.5), y.interpolate(x, 0.5), atol=1e-9)


# ------------------------------------------------------------------------- Jacobians


def test_right_and_left_jacobians(group, batch_shape, rng):
    tangent = random_tangent(group, rng, batch_shape)
    n = group.dof
    jr = numerical_jacobian(group.exp, tangent, n, input_on_group=False, output_on_group=True)
    np.testing.assert_allclose(group.jr(tangent), jr, atol=JACOBIAN_ATOL)
    x = group.exp(tangent)
    jr_inv = numerical_jacobian(lambda y: y.log(), x, n, True, False)
    np.testing.assert_allclose(group.jr_inv(tangent), jr_inv, atol=JACOBIAN_ATOL)
    # Left Jacobian: Exp(ξ + dξ) ≈ Exp(jl dξ) Exp(ξ); numerically, Log(Exp(ξ + dξ) Exp(ξ)⁻¹).
    h = 1e-6
    columns = []
    for k in range(n):
        d = np.zeros_like(tangent)
        d[..., k] = h
        plus = (group.exp(tangent + d) @ x.inverse()).log()
        minus = (group.exp(tangent - d) @ x.inverse()).log()
        columns.append((plus - minus) / (2 * h))
    jl = np.stack(columns, axis=-1)
    np.testing.assert_allclose(group.jl(tangent), jl, atol=JACOBIAN_ATOL)
    np.testing.assert_allclose(
        group.jl_inv(tangent) @ jl, np.broadcast_to(np.eye(n), jl.shape), atol=1e-6
    )


def test_compose_inverse_between_jacobians(group, batch_shape, rng):
    x, y = group.sample(rng, batch_shape), group.sample(rng, batch_shape)
    n = group.dof
    _, j_x, j_y = x.compose_with_jacobians(y)
    np.testing.assert_allclose(
        j_x, numerical_jacobian(lambda a: a @ y, x, n, True, True), atol=JACOBIAN_ATOL
    )
    np.testing.assert_allclose(
        j_y, numerical_jacobian(lambda b: x @ b, y, n, True, True), atol=JACOBIAN_ATOL
    )
    _, j_inv = x.inverse_with_jacobians()
    np.testing.assert_allclose(
        j_inv, numerical_jacobian(lambda a: a.inverse(), x, n, True, True), atol=JACOBIAN_ATOL
    )
    _, j_x, j_y = x.between_with_jacobians(y)
    np.testing.assert_allclose(
        j_x, numerical_jacobian(lambda a: a.between(y), x, n, True, True), atol=JACOBIAN_ATOL
    )
    np.testing.assert_allclose(
        j_y, numerical_jacobian(lambda b: x.between(b), y, n, True, True), atol=JACOBIAN_ATOL
    )


def test_log_and_act_jacobians(group, batch_shape, rng):
    x = group.exp(random_tangent(group, rng, batch_shape))
    n = group.dof
    _, j_log = x.log_with_jacobians()
    np.testing.assert_allclose(
        j_log, numerical_jacobian(lambda a: a.log(), x, n, True, False), atol=JACOBIAN_ATOL
    )
    points = rng.normal(size=batch_shape + (group.point_dim,))
    moved, j_x, j_p = x.act_with_jacobians(points)
    np.testing.assert_allclose(moved, x @ points, atol=1e-14)
    np.testing.assert_allclose(
        j_x, numerical_jacobian(lambda a: a @ points, x, n, True, False), atol=JACOBIAN_ATOL
    )
    numeric_p = numerical_jacobian(lambda p: x @ p, points, group.point_dim, False, False)
    np.testing.assert_allclose(j_p, numeric_p, atol=JACOBIAN_ATOL)


def test_exp_retract_local_interpolate_jacobians(group, batch_shape, rng):
    """Each against central differences on the manifold."""
    n = group.dof
    x = group.exp(random_tangent(group, rng, batch_shape))
    y = x.retract(random_tangent(group, rng, batch_shape) * 0.5)
    tangent = random_tangent(group, rng, batch_shape)
    _, j_exp = group.exp_with_jacobians(tangent)
    np.testing.assert_allclose(
        j_exp, numerical_jacobian(group.exp, tangent, n, False, True), atol=JACOBIAN_ATOL
    )
    value, j_x, j_delta = x.retract_with_jacobians(tangent)
    assert_same_element(value, x.retract(tangent))
    np.testing.assert_allclose(
        j_x, numerical_jacobian(lambda a: a.retract(tangent), x, n, True, True), atol=JACOBIAN_ATOL
    )
    np.testing.assert_allclose(
        j_delta, numerical_jacobian(x.retract, tangent, n, False, True), atol=JACOBIAN_ATOL
    )
    local, j_x, j_y = x.local_with_jacobians(y)
    np.testing.assert_allclose(local, x.local(y), atol=1e-12)
    np.testing.assert_allclose(
        j_x, numerical_jacobian(lambda a: a.local(y), x, n, True, False), atol=JACOBIAN_ATOL
    )
    np.testing.assert_allclose(
        j_y, numerical_jacobian(x.local, y, n, True, False), atol=JACOBIAN_ATOL
    )
    np.testing.assert_allclose(j_x, -group.jl_inv(local), atol=1e-9)
    value, j_x, j_y = x.interpolate_with_jacobians(y, 0.3)
    assert_same_element(value, x.interpolate(y, 0.3))
    np.testing.assert_allclose(
        j_x,
        numerical_jacobian(lambda a: a.interpolate(y, 0.3), x, n, True, True),
        atol=JACOBIAN_ATOL,
    )
    np.testing.assert_allclose(
        j_y,
        numerical_jacobian(lambda b: x.interpolate(b, 0.3), y, n, True, True),
        atol=JACOBIAN_ATOL,
    )


def test_bch_agrees_with_log_of_the_product_to_fourth_order(group, batch_shape, rng):
    """|Log(Exp(tx) Exp(ty)) − bch(tx, ty)| = O(t⁴): halving t divides it by about 16."""
    x, y = random_tangent(group, rng, batch_shape), random_tangent(group, rng, batch_shape)

    def error(t: float) -> float:
        exact = (group.exp(t * x) @ group.exp(t * y)).log()
        return float(np.abs(exact - group.bch(t * x, t * y)).max())

    coarse, fine = error(0.02), error(0.01)
    assert fine < coarse / 12 or fine < 1e-13, (coarse, fine)
    np.testing.assert_allclose(group.bch(x, np.zeros_like(x)), x, atol=1e-15)
