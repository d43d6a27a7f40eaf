"""Uncertainty on groups: propagation, fusion, and the intrinsic mean (Eade §8)."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.lie import SE2, SE3, SO3, Sim3
from posegraph.lie.uncertainty import (
    compose_covariance,
    fuse,
    inverse_covariance,
    mean_and_covariance,
    sample_gaussian,
)

from ..helpers import assert_same_element, numerical_jacobian

GROUPS = [SE2, SO3, SE3, Sim3]


def _random_covariance(rng, dof, scale=1e-2):
    a = rng.normal(size=(dof, dof))
    return scale * (a @ a.T / dof + 0.1 * np.eye(dof))


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_propagation_matches_numerical_jacobians(group):
    rng = np.random.default_rng(10)
    x, y = group.sample(rng), group.sample(rng)
    cx, cy = _random_covariance(rng, group.dof), _random_covariance(rng, group.dof)
    cross = 0.1 * _random_covariance(rng, group.dof)
    ja = numerical_jacobian(lambda a: a @ y, x, group.dof, True, True)
    jb = numerical_jacobian(lambda b: x @ b, y, group.dof, True, True)
    expected = ja @ cx @ ja.T + jb @ cy @ jb.T + ja @ cross @ jb.T + jb @ cross.T @ ja.T
    np.testing.assert_allclose(compose_covariance(x, cx, y, cy, cross), expected, atol=1e-9)
    ji = numerical_jacobian(lambda a: a.inverse(), x, group.dof, True, True)
    np.testing.assert_allclose(inverse_covariance(x, cx), ji @ cx @ ji.T, atol=1e-9)


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_sampled_mean_and_covariance(group):
    rng = np.random.default_rng(11)
    mean = group.sample(rng)
    covariance = _random_covariance(rng, group.dof, scale=1e-3)
    samples = sample_gaussian(mean, covariance, rng, 20000)
    estimate, estimated_covariance = mean_and_covariance(samples)
    standard_error = np.sqrt(np.diag(covariance) / 20000)
    assert np.all(np.abs(estimate.local(mean)) < 5 * standard_error)
    np.testing.assert_allclose(
        estimated_covariance, covariance, atol=0.05 * np.abs(covariance).max()
    )


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_fusion_of_identical_estimates_halves_the_covariance(group):
    rng = np.random.default_rng(12)
    x = group.sample(rng)
    c = _random_covariance(rng, group.dof)
    fused, fused_covariance = fuse(x, c, x, c)
    assert_same_element(fused, x, atol=1e-12)
    np.testing.assert_allclose(fused_covariance, c / 2, atol=1e-14)


def test_fusion_of_two_rotations_is_the_geodesic_midpoint():
    """With equal isotropic covariances on SO(3) the fused mean is the midpoint of the geodesic."""
    rng = np.random.default_rng(13)
    a, b = SO3.sample(rng), SO3.sample(rng)
    fused, _ = fuse(a, 0.1 * np.eye(3), b, 0.1 * np.eye(3))
    assert_same_element(fused, a.interpolate(b, 0.5), atol=1e-10)


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_fusion_of_close_estimates_is_the_information_form(group):
    """For nearby estimates the fusion tends to the linear Kalman update."""
    rng = np.random.default_rng(14)
    x = group.sample(rng)
    c1, c2 = _random_covariance(rng, group.dof), _random_covariance(rng, group.dof)
    d = 1e-6 * rng.normal(size=group.dof)
    fused, covariance = fuse(x, c1, x.retract(d), c2)
    info1, info2 = np.linalg.inv(c1), np.linalg.inv(c2)
    expected_covariance = np.linalg.inv(info1 + info2)
    np.testing.assert_allclose(
        covariance, expected_covariance, atol=1e-5 * np.abs(expected_covariance).max()
    )
    np.testing.assert_allclose(x.local(fused), expected_covariance @ info2 @ d, atol=1e-11)
