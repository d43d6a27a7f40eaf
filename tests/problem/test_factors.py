"""Residuals, Jacobians and cost of between edges and priors (CONVENTIONS.md)."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.problem.factors import chi2, linearize_between, linearize_priors

from ..conftest import POSE_GROUPS, random_graph


@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_between_residual_definition(group):
    graph = random_graph(group, 6, 3, seed=1)
    x, e = graph.values, graph.edges
    lin = linearize_between(x, e)
    for k in range(len(e)):
        xi, xj, z = x[e.i[k]], x[e.j[k]], e.measurements[k]
        expected = (z.inverse() @ xi.inverse() @ xj).log()
        np.testing.assert_allclose(lin.residuals[k], expected, atol=1e-12)


def _residual_jacobian(linearize, values, edges, edge: int, node: int, dof: int, h: float = 1e-6):
    """Central differences of edge ``edge``'s residual in node ``node``'s right perturbation."""
    columns = []
    for c in range(dof):
        delta = np.zeros((values.batch_shape[0], dof))
        delta[node, c] = h
        plus = linearize(values.retract(delta), edges).residuals[edge]
        minus = linearize(values.retract(-delta), edges).residuals[edge]
        columns.append((plus - minus) / (2 * h))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_between_jacobians_match_central_differences(group):
    graph = random_graph(group, 6, 4, seed=2, noise=0.3)
    x, e = graph.values, graph.edges
    lin = linearize_between(x, e)
    for k in range(len(e)):
        for node, analytic in ((e.i[k], lin.jac_i[k]), (e.j[k], lin.jac_j[k])):
            numeric = _residual_jacobian(linearize_between, x, e, k, node, group.dof)
            np.testing.assert_allclose(analytic, numeric, atol=1e-7)


@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_prior_residual_and_jacobian(group):
    graph = random_graph(group, 5, 0, seed=3, priors=3)
    x, p = graph.values, graph.priors
    lin = linearize_priors(x, p)
    for k in range(len(p)):
        expected = (p.measurements[k].inverse() @ x[p.i[k]]).log()
        np.testing.assert_allclose(lin.residuals[k], expected, atol=1e-12)
        numeric = _residual_jacobian(linearize_priors, x, p, k, p.i[k], group.dof)
        np.testing.assert_allclose(lin.jac_j[k], numeric, atol=1e-7)


def test_chi2_is_the_weighted_sum_of_squares():
    graph = random_graph(POSE_GROUPS[1], 7, 4, seed=4, priors=2)
    total = 0.0
    for edges, lin in (
        (graph.edges, linearize_between(graph.values, graph.edges)),
        (graph.priors, linearize_priors(graph.values, graph.priors)),
    ):
        for r, omega in zip(lin.residuals, edges.information, strict=True):
            total += r @ omega @ r
    assert np.isclose(chi2(graph.values, graph.edges, graph.priors), total, rtol=1e-13)
