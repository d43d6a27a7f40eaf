"""Noise consistency: χ² per redundant degree of freedom is 1 where the information states the
simulated noise, and names information scaled away from it and false loops."""

from __future__ import annotations

import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph.graph import EdgeSet
from posegraph.robust.noise import noise_consistency


@pytest.fixture(scope="module")
def simulated():
    """A manhattan world whose measurements' noise is what their information states."""
    graph, _ = manhattan_world(1000, seed=3)
    return graph, posegraph.optimize(graph).values


def test_information_that_states_the_noise_gives_one_per_degree_of_freedom(simulated):
    graph, values = simulated
    classes = noise_consistency(graph, values)
    assert [c.kind for c in classes] == ["odometry", "loop closures"]
    for noise_class in classes:
        assert noise_class.chi2_per_dof == pytest.approx(1.0, abs=0.1)
        assert noise_class.above_quantile <= 0.005 * noise_class.count
        assert noise_class.finding() is None
    # The redundancy numbers add up to the redundancy of the problem: measured degrees of
    # freedom less the poses' (one held).
    redundancy = sum(c.redundancy for c in classes)
    assert redundancy == pytest.approx(3 * graph.num_edges - 3 * (graph.num_nodes - 1), rel=1e-3)


def test_scaled_information_is_named_with_its_factor(simulated):
    graph, values = simulated
    scaled = graph.copy()
    edges = scaled.edges
    scaled.edges = EdgeSet(edges.i, edges.j, edges.measurements, edges.information * 1e-4)
    for noise_class in noise_consistency(scaled, posegraph.optimize(scaled).values):
        what, suggestion = noise_class.finding()
        assert f"the information of the {noise_class.kind} overstates their noise about" in what
        assert 9e3 < 1 / noise_class.chi2_per_dof < 1.1e4
        assert "--calibrate-noise" in suggestion


def test_noise_free_measurements_are_not_a_finding(simulated):
    """Residuals of exactly 0 (a file made without noise) say nothing of the information."""
    graph, values = simulated
    exact = graph.copy()
    relative = values[exact.edges.i].between(values[exact.edges.j])
    exact.edges = EdgeSet(exact.edges.i, exact.edges.j, relative, exact.edges.information)
    classes = noise_consistency(exact, values)
    assert all(c.chi2_per_dof < 1e-20 and c.finding() is None for c in classes)


def test_false_loops_are_named(simulated):
    graph, _ = simulated
    corrupted, false = add_false_loops(graph, 0.1, seed=0)
    classes = noise_consistency(corrupted, posegraph.optimize(corrupted).values)
    loops = next(c for c in classes if c.kind == "loop closures")
    what, suggestion = loops.finding()
    assert "loop closures fail the χ²(0.999) test" in what and "likely false loops" in what
    assert suggestion == "try --robust gnc"
    assert loops.above_quantile >= false.sum()
