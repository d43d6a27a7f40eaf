"""exp, log, compose, inverse and adjoint against gtsam's Rot2, Pose2, Rot3, Pose3, Similarity3."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.lie import gtsam_order

from ..helpers import POSE_GROUPS, assert_same_element, random_tangent

gtsam = pytest.importorskip("gtsam")
bridge = pytest.importorskip("posegraph.validation.gtsam_bridge")

COUNT = 25
TOL = 1e-10


@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_agreement_with_gtsam(group):
    rng = np.random.default_rng(30)
    gtsam_type = bridge.GTSAM_TYPE[group]
    tangents = random_tangent(group, rng, (COUNT,))
    xs, ys = group.sample(rng, (COUNT,)), group.sample(rng, (COUNT,))
    for k in range(COUNT):
        x, y = xs[k], ys[k]
        gx, gy = bridge.to_gtsam(x), bridge.to_gtsam(y)
        assert_same_element(bridge.from_gtsam(gx), x, atol=1e-14)
        expected_exp = bridge.from_gtsam(
            gtsam_type.Expmap(gtsam_order.tangent_to_gtsam(group, tangents[k]))
        )
        assert_same_element(group.exp(tangents[k]), expected_exp, atol=TOL)
        expected_log = gtsam_order.tangent_from_gtsam(group, np.atleast_1d(gtsam_type.Logmap(gx)))
        np.testing.assert_allclose(x.log(), expected_log, atol=TOL)
        assert_same_element(x @ y, bridge.from_gtsam(gx.compose(gy)), atol=TOL)
        assert_same_element(x.inverse(), bridge.from_gtsam(gx.inverse()), atol=TOL)
        assert_same_element(x.between(y), bridge.from_gtsam(gx.between(gy)), atol=TOL)
        adjoint = np.atleast_2d(gx.AdjointMap())
        np.testing.assert_allclose(
            gtsam_order.matrix_to_gtsam(group, x.adjoint()), adjoint, atol=TOL
        )
