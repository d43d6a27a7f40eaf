"""IRLS kernels and widths, priors under the kernel, and the robust cost a run reports."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.stats as scipy_stats
from posegraph_datasets.generators import manhattan_world, sphere
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.graph import PoseGraph
from posegraph.init.choice import initialize
from posegraph.init.chordal import chordal_values
from posegraph.lie import SE2
from posegraph.problem.factors import (
    between_squares,
    chi2,
    prior_residuals,
    weighted_squares,
)
from posegraph.robust.anchoring import priors_as_edges
from posegraph.robust.kernels import KERNELS, RobustKernel, default_width, tls_gnc_weights
from posegraph.robust.spec import KERNEL_QUANTILE, gnc_quantile, robust_mask
from tests.robust.helpers import gnss_with_a_bad_fix

from ..conftest import (
    city_with_fixes,
)


def _robust_cost(graph, values, kernel, loops, robust_priors):
    """½ Σ ρ(s) over the loops (and the priors, with ``robust_priors``), ½ Σ s over the rest;
    ρ(s) = min(s, c²) for "gnc", else the kernel's."""
    if kernel == "gnc":
        measured = int(loops.sum()) + (len(graph.priors) if robust_priors else 0)
        width_sq = default_width(graph.group.dof, gnc_quantile(measured)) ** 2
        rho = lambda s: np.minimum(s, width_sq)  # noqa: E731
    else:
        rho = RobustKernel(kernel, default_width(graph.group.dof, KERNEL_QUANTILE)).cost
    edges = between_squares(values, graph.edges)
    priors = weighted_squares(prior_residuals(values, graph.priors), graph.priors.information)
    edge_costs = np.where(loops, rho(edges), edges)
    return 0.5 * (edge_costs.sum() + (rho(priors) if robust_priors else priors).sum())


@pytest.mark.parametrize("name", KERNELS)
def test_kernel_weight_is_the_derivative_of_its_cost(name):
    kernel = RobustKernel(name, 1.7)
    s = np.concatenate([np.linspace(1e-6, 10.0, 200), [0.5 * 1.7**2, 1.7**2 * 0.999]])
    h = 1e-6
    numeric = (kernel.cost(s + h) - kernel.cost(s - h)) / (2 * h)
    np.testing.assert_allclose(kernel.weight(s), numeric, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(kernel.cost(np.array([1e-9])), 1e-9, rtol=1e-6)  # ρ(s) ≈ s near 0
    assert np.all(np.diff(kernel.cost(s[:200])) >= 0)


@pytest.mark.parametrize("name", KERNELS)
def test_kernels_take_a_square_that_rounding_made_negative(name):
    """s = rᵀΩr is −1e-17 when Ω's least eigenvalue is −1e-17 (information may be singular
    to rounding): ρ(s) ≈ s and w = 1 there, without numpy's warnings."""
    kernel = RobustKernel(name, 1.7)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cost, weight = kernel.cost(np.array([-1e-17])), kernel.weight(np.array([-1e-17]))
    np.testing.assert_allclose(cost, -1e-17, atol=1e-16)
    np.testing.assert_allclose(weight, 1.0, rtol=1e-12)


@pytest.mark.parametrize("dof", [1, 2, 3, 6, 7])
def test_default_width_is_the_chi2_quantile(dof):
    from scipy.stats import chi2

    for quantile in (0.5, 0.9, 0.99, 0.999):
        expected = np.sqrt(chi2.ppf(quantile, dof))
        assert default_width(dof, quantile) == pytest.approx(expected, rel=1e-12)


def test_tls_gnc_weights_follow_yang_et_al():
    s = np.array([0.0, 0.5, 4.0, 100.0])
    mu, c2 = 1.0, 4.0
    w = tls_gnc_weights(s, c2, mu)
    assert w[0] == 1.0 and w[1] == 1.0 and w[3] == 0.0
    np.testing.assert_allclose(w[2], np.sqrt(c2 * mu * (mu + 1) / 4.0) - mu)
    assert np.all(tls_gnc_weights(np.linspace(0, 50, 100), c2, 1e6) >= -1e-12)


def test_robust_edges_given_by_the_caller_cover_a_closure_between_consecutive_nodes():
    """Two robots in one graph: robot B's poses (100–199) follow robot A's (0–99), so an
    inter-robot closure from A's last pose to B's first joins consecutive nodes, which the
    "loops" class trusts as odometry. A false one then bends the map, and GNC rejects true loops
    in its place. Given the class as a mask of every edge but the odometry, or as the indices
    of those edges, GNC rejects the false closure alone and ends at the outlier-free optimum."""
    graph, _ = manhattan_world(num_poses=200, seed=67)
    graph.remove_edges(np.flatnonzero((graph.edges.i == 99) & (graph.edges.j == 100)).tolist())
    odometry = ~robust_mask(graph, "loops")
    clean = posegraph.optimize(graph.copy()).values
    graph.add_edge(99, 100, SE2.from_xytheta([3.0, -2.0, 1.0]), np.eye(3) * 100.0)
    false_closure = graph.num_edges - 1
    closures = ~np.append(odometry, False)

    def distance_to_clean(values):
        return np.linalg.norm(values.translation - clean.translation, axis=1).max()

    trusted = posegraph.optimize(graph.copy(), robust="gnc", robust_edges="loops")
    assert false_closure not in trusted.summary.rejected_edges
    assert distance_to_clean(trusted.values) > 0.5
    by_mask = posegraph.optimize(graph.copy(), robust="gnc", robust_edges=closures)
    assert by_mask.summary.rejected_edges == [false_closure]
    assert by_mask.summary.edges_under_kernel == closures.sum()
    assert trusted.summary.edges_under_kernel == closures.sum() - 1  # all but the false closure
    assert distance_to_clean(by_mask.values) < 1e-6
    by_index = posegraph.optimize(graph.copy(), robust="gnc", robust_edges=np.flatnonzero(closures))
    assert by_index.summary.rejected_edges == [false_closure]
    np.testing.assert_array_equal(by_index.values.as_matrix(), by_mask.values.as_matrix())


@pytest.mark.parametrize("kernel", ["cauchy", "dcs", "huber", "geman-mcclure", "tukey"])
def test_irls_kernels_resist_false_loops(kernel):
    """IRLS kernels refine locally: from a good start they ignore false loops that pull plain
    least squares away (GNC, above, is the tool that needs no good start)."""
    graph, _ = sphere(rings=6, poses_per_ring=16, seed=68)
    clean = posegraph.optimize(graph.copy())
    corrupted, false = add_false_loops(graph, 0.1, seed=3)
    corrupted.set_values(chordal_values(graph))
    robust = posegraph.optimize(corrupted.copy(), init="file", robust=kernel)
    plain = posegraph.optimize(corrupted.copy(), init="file")
    error = lambda r: np.linalg.norm(r.values.translation - clean.values.translation, axis=1).mean()  # noqa: E731
    assert error(robust) < 0.2 * error(plain)
    assert robust.summary.robust.startswith(kernel)
    assert set(np.flatnonzero(false)) <= set(robust.summary.rejected_edges)


def test_priors_as_edges_from_a_held_world_node_keep_the_cost_and_the_optimum():
    graph, _ = city_with_fixes(0.0, seed=0)
    anchored = priors_as_edges(graph)
    assert len(anchored.priors) == 0 and anchored.fixed[-1] and not anchored.fixed[:-1].any()
    assert chi2(anchored.values, anchored.edges, anchored.priors) == pytest.approx(
        chi2(graph.values, graph.edges, graph.priors), rel=1e-12
    )
    direct = posegraph.optimize(graph.copy(), init="file")
    as_edges = posegraph.optimize(anchored, init="file")
    assert as_edges.summary.final_error == pytest.approx(direct.summary.final_error, rel=1e-9)
    assert as_edges.summary.num_variables == direct.summary.num_variables
    np.testing.assert_allclose(
        as_edges.values[:-1].as_matrix(), direct.values.as_matrix(), atol=1e-7
    )
    np.testing.assert_array_equal(as_edges.values[-1].as_matrix(), np.eye(3))


def test_irls_kernels_weigh_a_position_only_fix_by_the_width_of_its_three_directions():
    """Huber on position-only fixes: each prior's weight is min(1, c/√s) with c = √χ²₃(0.95)."""
    graph = gnss_with_a_bad_fix(4.0)
    smoother = posegraph.Smoother(graph)
    result = smoother.optimize(robust="huber", robust_priors=True)
    squares = weighted_squares(
        prior_residuals(result.values, graph.priors), graph.priors.information
    )
    width = np.sqrt(scipy_stats.chi2.ppf(KERNEL_QUANTILE, 3))
    assert squares[5] > width**2
    np.testing.assert_allclose(
        smoother.solution.prior_weights, np.minimum(1.0, width / np.sqrt(squares)), rtol=1e-6
    )


def test_robust_priors_on_a_graph_without_priors_change_nothing():
    """Nothing to anchor: an empty graph has nothing to optimise (the world node's id was taken
    from the largest of no ids), and a graph without priors is solved as without the flag."""
    empty = posegraph.optimize(PoseGraph("SE2"), robust="gnc", robust_priors=True)
    assert empty.summary.termination == "nothing to optimise"
    graph, _ = manhattan_world(num_poses=60, seed=5)
    corrupted, false = add_false_loops(graph, 0.2, seed=0)
    flagged = posegraph.optimize(corrupted.copy(), robust="gnc", robust_priors=True)
    plain = posegraph.optimize(corrupted.copy(), robust="gnc")
    assert flagged.summary.rejected_edges == plain.summary.rejected_edges
    assert flagged.summary.rejected_priors == []
    np.testing.assert_array_equal(flagged.values.as_matrix(), plain.values.as_matrix())


def test_irls_kernels_weigh_priors_with_robust_priors():
    """Huber on the loops and the priors: the final error is ½ (Σ ρ(s) over the loops and the
    priors + Σ s over the odometry) at the solution, and each prior's weight is ρ′(s) there."""
    graph, false = city_with_fixes(0.3, seed=1)
    smoother = posegraph.Smoother(graph)
    result = smoother.optimize(robust="huber", robust_priors=True)
    kernel = RobustKernel("huber", default_width(3, KERNEL_QUANTILE))
    loops = robust_mask(graph, "loops")
    edge_squares = between_squares(result.values, graph.edges)
    prior_squares = weighted_squares(
        prior_residuals(result.values, graph.priors), graph.priors.information
    )
    expected = 0.5 * (
        np.where(loops, kernel.cost(edge_squares), edge_squares).sum()
        + kernel.cost(prior_squares).sum()
    )
    assert result.summary.final_error == pytest.approx(expected, rel=1e-9)
    np.testing.assert_allclose(
        smoother.solution.prior_weights, kernel.weight(prior_squares), rtol=1e-6
    )
    weights = smoother.solution.prior_weights
    assert weights[false].max() < 0.5 < 0.8 < weights[~false].min()
    assert set(np.flatnonzero(false)) <= set(result.summary.rejected_priors)


@pytest.mark.parametrize("robust_priors", [False, True], ids=["trusted fixes", "robust fixes"])
@pytest.mark.parametrize("kernel", ["gnc", "cauchy"])
def test_a_robust_run_reports_its_robust_cost_from_input_to_solution(kernel, robust_priors):
    """The errors of a robust run (input values, initial values, solution) are all the robust
    cost, the one minimised; a GNC run's stop at the outlier-free solution counts c²/2 for each
    rejected loop. Before, the input error was least squares', and GNC's initial and final
    errors were those of its last solve, over the kept edges only."""
    graph, _ = city_with_fixes(0.3, seed=2)
    corrupted, _ = add_false_loops(graph, 0.1, seed=4)
    loops = robust_mask(corrupted, "loops")
    given = corrupted.values
    start = initialize(corrupted, "odometry")
    result = posegraph.optimize(corrupted, robust=kernel, robust_priors=robust_priors)
    summary = result.summary
    for error, values in (
        (summary.input_error, given),
        (summary.initial_error, start),
        (summary.final_error, result.values),
    ):
        assert error == pytest.approx(
            _robust_cost(corrupted, values, kernel, loops, robust_priors), rel=1e-9
        )
