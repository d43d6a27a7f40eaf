"""The Sim3 scale-drift graph in gtsam (BetweenFactorSimilarity3) and in g2o (EdgeSim3)."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.monocular import monocular_sequence

import posegraph
from posegraph.init.chordal import chordal_values
from posegraph.problem.factors import chi2
from posegraph.sim3.scale_drift import lifting_scale_information

gtsam = pytest.importorskip("gtsam")
bridge = pytest.importorskip("posegraph.validation.gtsam_bridge")


@pytest.fixture(scope="module")
def graph():
    graph = monocular_sequence(num_poses=150, drift=0.01, seed=6).sim3_graph()
    graph.set_values(chordal_values(graph))
    return graph


@pytest.fixture(scope="module")
def quiet_graph():
    """The same sequence with 10× less noise, lifted with the odometry's own scale information
    (the loops call for a weaker one): gtsam's Sim3 between factor omits the Logmap Jacobian,
    which is exact only at zero residual, so its LM stalls short of the optimum by an amount
    that grows with the residuals (1e-5 relative with the weaker lift)."""
    sequence = monocular_sequence(
        num_poses=150,
        drift=0.01,
        seed=6,
        translation_sigma=0.002,
        rotation_sigma=0.0002,
        scale_sigma=0.001,
    )
    graph = sequence.sim3_graph(lifting_scale_information(sequence.odometry, None))
    graph.set_values(chordal_values(graph))
    return graph


def test_gtsam_agrees_on_cost_at_the_same_values(graph):
    factors, values = bridge.graph_to_gtsam(graph, hold_gauge=False)
    assert factors.error(values) == pytest.approx(
        0.5 * chi2(graph.values, graph.edges, graph.priors), rel=1e-6
    )


def test_gtsam_agrees_on_the_optimum(quiet_graph):
    """From the same values: final costs within 1e-6 relative (ours no higher); poses within
    1e-4: rotation and log-scale in the tangent, positions relative to the scene's extent."""
    graph = quiet_graph
    ours = posegraph.optimize(graph.copy(), init="file")
    factors, values = bridge.graph_to_gtsam(graph)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(200)
    theirs = gtsam.LevenbergMarquardtOptimizer(factors, values, params).optimize()
    their_error = factors.error(theirs)
    assert ours.summary.final_error <= their_error * (1 + 1e-6)
    assert their_error == pytest.approx(ours.summary.final_error, rel=1e-6)
    their_values = bridge.values_from_gtsam(graph, theirs)
    difference = ours.values.local(their_values)
    assert np.abs(difference[:, 3:]).max() < 1e-4  # rotation and log-scale
    extent = np.ptp(ours.values.translation, axis=0).max()
    assert np.abs(their_values.translation - ours.values.translation).max() < 1e-4 * extent


def test_g2o_chi2_agrees(graph):
    """g2opy's EdgeSim3 χ² at our initial values and at our optimum, within 1e-6 relative."""
    g2o = pytest.importorskip("g2opy")
    ours = posegraph.optimize(graph.copy(), init="file")
    for values in (graph.values, ours.values):
        vertices = []
        for k in range(graph.num_nodes):
            vertex = g2o.VertexSim3Expmap()
            vertex.set_id(k)
            s = values[k].inverse()  # g2o's vertex is the world → camera element Sᵢ = Xᵢ⁻¹
            vertex.set_estimate(g2o.Sim3(s.rotation, s.translation, float(s.scale)))
            vertices.append(vertex)
        total = 0.0
        order = [3, 4, 5, 0, 1, 2, 6]  # g2o's tangent (ω, υ, σ) from ours (ρ, φ, σ)
        for e in range(graph.num_edges):
            edge = g2o.EdgeSim3()
            edge.set_vertex(0, vertices[graph.edges.i[e]])
            edge.set_vertex(1, vertices[graph.edges.j[e]])
            z = graph.edges.measurements[e].inverse()  # g2o's Z is our measurement's inverse
            edge.set_measurement(g2o.Sim3(z.rotation, z.translation, float(z.scale)))
            edge.set_information(graph.edges.information[e][np.ix_(order, order)])
            edge.compute_error()
            total += edge.chi2()
        assert total == pytest.approx(chi2(values, graph.edges, graph.priors), rel=1e-6)


def test_the_scale_drift_benchmark_runs_gtsam_on_the_same_graph():
    """``python -m posegraph.benchmarks.scale_drift --gtsam`` on one sequence of 60 keyframes:
    gtsam's final error (from the dead-reckoning values) is posegraph's to 1e-4 relative and
    not below it, and the time ratio is that of the two times in the row."""
    from posegraph.benchmarks import scale_drift

    header, _, row = str(scale_drift.run([0.01], [0], gtsam=True, poses=60)).splitlines()
    names = (name.strip() for name in header.strip("|").split("|"))
    cells = dict(zip(names, row.strip("|").split("|"), strict=True))
    ours, theirs = float(cells["error"]), float(cells["gtsam error"])
    assert theirs >= ours * (1 - 1e-9)
    assert theirs == pytest.approx(ours, rel=1e-4)
    ratio = float(cells["posegraph (ms)"]) / float(cells["gtsam (ms)"])
    assert float(cells["time ratio"]) == pytest.approx(ratio, rel=0.05, abs=0.01)
