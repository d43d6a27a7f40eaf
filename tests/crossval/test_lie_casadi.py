"""Analytic Jacobians against casadi's automatic derivatives of an independent model."""

from __future__ import annotations

import numpy as np
import pytest

from ..helpers import ALL_GROUPS, random_tangent

casadi_model = pytest.importorskip("posegraph.validation.casadi_model")

POINTS = 100


@pytest.mark.parametrize("group", ALL_GROUPS, ids=lambda g: g.__name__)
def test_jacobians_equal_casadi(group):
    rng = np.random.default_rng(20)
    a = random_tangent(group, rng, (POINTS,))
    b = random_tangent(group, rng, (POINTS,))
    p = rng.normal(size=(POINTS, group.point_dim))
    x, y = group.exp(a), group.exp(b)
    ours = {
        "jr": group.jr(a),
        "jl": group.jl(a),
        "jr_inv": group.jr_inv(a),
        "jl_inv": group.jl_inv(a),
    }
    _, ours["compose_a"], ours["compose_b"] = x.compose_with_jacobians(y)
    _, ours["inverse"] = x.inverse_with_jacobians()
    _, ours["between_a"], ours["between_b"] = x.between_with_jacobians(y)
    _, ours["log"] = x.log_with_jacobians()
    _, ours["act_element"], ours["act_point"] = x.act_with_jacobians(p)
    _, ours["exp"] = group.exp_with_jacobians(a)
    _, ours["retract_a"], ours["retract_b"] = x.retract_with_jacobians(b)
    if casadi_model.has_log(group):
        _, ours["local_a"], ours["local_b"] = x.local_with_jacobians(y)
        weight = casadi_model.INTERPOLATION_WEIGHT
        _, ours["interpolate_a"], ours["interpolate_b"] = x.interpolate_with_jacobians(y, weight)
    symbolic = casadi_model.jacobian_functions(group)
    reference = {name: function(a, b, p) for name, function in symbolic.items()}
    if not casadi_model.has_log(group):
        # No symbolic Log for the matrix groups: the inverse Jacobians are checked as inverses of
        # casadi's jr and jl (Log's Jacobian is jr⁻¹ of Log X = a).
        reference["jr_inv"] = reference["log"] = np.linalg.inv(reference["jr"])
        reference["jl_inv"] = np.linalg.inv(reference["jl"])
    assert set(reference) == set(ours)
    for name, expected in reference.items():
        np.testing.assert_allclose(ours[name], expected, rtol=1e-9, atol=1e-9, err_msg=name)
