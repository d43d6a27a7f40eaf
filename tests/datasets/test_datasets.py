"""The bundled examples are exactly what the project's own generators write."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets import EXAMPLES_DIR, example
from posegraph_datasets.generators import docked, manhattan_world, resimulate, sphere
from posegraph_datasets.make_examples import example_texts

from posegraph.problem.factors import between_residuals
from posegraph.solvers import solve


def test_bundled_examples_regenerate(tmp_path):
    """Same lines, same ids, same numbers to 1e-12 (the last printed digit of a float may
    differ between CPUs, whose vectorised sin and cos can differ in the last bit)."""
    for name, text in example_texts().items():
        fresh = tmp_path / name
        fresh.write_text(text)
        committed, regenerated = (EXAMPLES_DIR / name).read_text().split(), text.split()
        assert len(committed) == len(regenerated), f"{name} differs: rerun make_examples"
        words = [(a, b) for a, b in zip(committed, regenerated, strict=True) if a != b]
        for a, b in words:
            assert float(a) == pytest.approx(float(b), rel=1e-12, abs=1e-12), f"{name}: {a} vs {b}"


def test_unknown_example_names_the_available_ones():
    with pytest.raises(FileNotFoundError, match="manhattan_small.g2o"):
        example("nope.g2o")


def _docked_sphere(seed: int):
    return docked(*sphere(seed=seed), every=2, seed=seed)


@pytest.mark.parametrize(
    "generate", [manhattan_world, sphere, _docked_sphere], ids=["manhattan", "sphere", "docked"]
)
def test_optimum_recovers_the_ground_truth(generate):
    """With σ = 0.05 m / 0.01 rad noise the optimum is far closer to the truth than odometry."""
    graph, truth = generate(seed=3)
    result = solve(graph)
    aligned = truth[0] @ result.values[0].inverse() @ result.values  # same gauge as the truth
    error_after = np.linalg.norm(aligned.translation - truth.translation, axis=1).mean()
    error_before = np.linalg.norm(graph.values.translation - truth.translation, axis=1).mean()
    assert error_after < 0.3 * error_before
    dof = graph.num_edges * graph.group.dof - (graph.num_nodes - 1) * graph.group.dof
    assert result.summary.final_chi2 == pytest.approx(dof, rel=0.2)  # χ² ≈ its degrees of freedom


def test_the_dock_is_the_second_node_and_every_other_pose_measures_it():
    graph, truth = sphere(seed=4)
    with_dock, new_truth = docked(graph, truth, every=2, seed=4)
    assert with_dock.num_nodes == graph.num_nodes + 1
    sightings = with_dock.edges.j == 1
    every_other_pose = np.r_[0, np.arange(2, graph.num_nodes, 2) + 1]  # after the dock: + 1
    np.testing.assert_array_equal(with_dock.edges.i[sightings], every_other_pose)
    np.testing.assert_allclose(new_truth[2:].as_matrix(), truth[1:].as_matrix())
    np.testing.assert_allclose(with_dock.values[2:].as_matrix(), graph.values[1:].as_matrix())


def test_resimulate_draws_each_edge_with_its_full_information():
    """Whitened by a random, correlated information matrix per edge, the residuals of the
    resimulated measurements at the truth are standard normal: mean 0, covariance I."""
    graph, truth = manhattan_world(num_poses=3000, seed=1)
    rng = np.random.default_rng(7)
    factors = rng.normal(size=(graph.num_edges, 3, 3))
    information = 100 * (factors @ np.swapaxes(factors, 1, 2) + 0.1 * np.eye(3))  # σ < 0.4 rad
    graph.edges = dataclasses.replace(graph.edges, information=information)
    simulated = resimulate(graph, truth, seed=5)
    np.testing.assert_array_equal(simulated.edges.i, graph.edges.i)
    np.testing.assert_array_equal(simulated.edges.information, graph.edges.information)
    residuals = between_residuals(truth, simulated.edges)
    cholesky = np.linalg.cholesky(simulated.edges.information)  # Ω = L Lᵀ: Lᵀr ~ N(0, I)
    whitened = np.einsum("mji,mj->mi", cholesky, residuals)
    tolerance = 5 / np.sqrt(graph.num_edges)
    np.testing.assert_allclose(whitened.mean(axis=0), 0, atol=tolerance)
    np.testing.assert_allclose(np.cov(whitened.T), np.eye(3), atol=2 * tolerance)
    again = resimulate(graph, truth, seed=5).edges.measurements.translation
    np.testing.assert_array_equal(again, simulated.edges.measurements.translation)


def test_false_loops_anywhere_join_near_and_distant_nodes_with_the_files_loop_information():
    from posegraph_datasets.outliers import NEARBY, add_false_loops_anywhere

    from posegraph.graph import odometry_mask

    graph, _ = manhattan_world(400, seed=5)
    loops = ~odometry_mask(graph)
    corrupted, false = add_false_loops_anywhere(graph, 0.3, seed=1)
    assert false.sum() == round(0.3 / 0.7 * loops.sum())
    assert np.array_equal(corrupted.edges.information[~false], graph.edges.information)
    gaps = np.abs(corrupted.edges.i[false] - corrupted.edges.j[false])
    nearby = (gaps >= 2) & (gaps <= NEARBY)
    assert gaps.min() >= 2 and abs(nearby.mean() - 0.5) < 0.05
    loop_information = {m.tobytes() for m in graph.edges.information[loops]}
    assert all(m.tobytes() in loop_information for m in corrupted.edges.information[false])
    positions = graph.values.translation
    extent = positions.max(axis=0) - positions.min(axis=0)
    translations = corrupted.edges.measurements[false].translation
    assert (np.abs(translations) <= extent).all()
    assert (
        np.abs(translations).max(axis=0) > 0.8 * extent
    ).all()  # the whole extent, not odometry's
