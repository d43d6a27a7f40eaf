"""Information from standard deviations, and gtsam's tangent order for covariances."""

from __future__ import annotations

import numpy as np
import pytest

import posegraph
from posegraph import SE2, SE3, SO2, SO3, Sim3


def test_information_from_sigmas_follows_the_tangent_order():
    np.testing.assert_allclose(
        posegraph.information_from_sigmas(SE2, 0.1, 0.01), np.diag([100.0, 100.0, 10000.0])
    )
    expected = np.diag([1 / 0.01, 1 / 0.04, 1 / 0.09, 1e4, 1e4, 1e4, 400.0])
    np.testing.assert_allclose(
        posegraph.information_from_sigmas(Sim3, [0.1, 0.2, 0.3], 0.01, scale=0.05), expected
    )
    assert posegraph.information_from_sigmas(SO3, rotation=0.5).shape == (3, 3)
    assert posegraph.information_from_sigmas(SO2, rotation=0.5)[0, 0] == 4.0
    with pytest.raises(ValueError, match="needs the rotation"):
        posegraph.information_from_sigmas(SE3, 0.1)
    with pytest.raises(ValueError, match="no scale"):
        posegraph.information_from_sigmas(SE3, 0.1, 0.1, scale=0.1)
    with pytest.raises(ValueError, match="positive"):
        posegraph.information_from_sigmas(SE2, 0.0, 0.1)


def test_a_gtsam_covariance_moves_to_our_tangent_and_back():
    """gtsam's Pose3 covariance is over (ω, v): its rotation block comes first."""
    theirs = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])  # var(ωx…ωz), var(vx…vz)
    ours = posegraph.matrix_from_gtsam(SE3, theirs)
    np.testing.assert_array_equal(np.diag(ours), [4.0, 5.0, 6.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(posegraph.matrix_to_gtsam(SE3, ours), theirs)
    sim3 = np.arange(49.0).reshape(7, 7)
    np.testing.assert_array_equal(
        posegraph.matrix_from_gtsam(Sim3, posegraph.matrix_to_gtsam(Sim3, sim3)), sim3
    )
    np.testing.assert_array_equal(posegraph.matrix_to_gtsam(SE2, np.eye(3) * 2), np.eye(3) * 2)
