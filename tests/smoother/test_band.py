"""Band matrices against the dense matrices they hold, and the fixed-lag smoother's band
windows against dense ones."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import visual_odometry

from posegraph.graph import PoseGraph
from posegraph.lie import SE3
from posegraph.smoother import Smoother, marginal
from posegraph.smoother.band import BandMatrix


def _random_band(rng: np.random.Generator, size: int, bandwidth: int):
    """Entries (rows, columns, values) of a random symmetric matrix within ``bandwidth``, some
    repeated (they add up), and the dense matrix they sum to."""
    i, j = np.indices((size, size))
    inside = np.abs(i - j) <= bandwidth
    rows, columns = i[inside], j[inside]
    repeat = rng.integers(0, rows.size, rows.size // 3)
    rows, columns = np.concatenate([rows, rows[repeat]]), np.concatenate([columns, columns[repeat]])
    values = rng.normal(size=rows.size)
    dense = np.zeros((size, size))
    np.add.at(dense, (rows, columns), values)
    dense = dense + dense.T  # both triangles, as a window's blocks give them
    return (
        np.concatenate([rows, columns]),
        np.concatenate([columns, rows]),
        np.concatenate([values, values]),
        dense,
    )


@pytest.mark.parametrize(("size", "bandwidth"), [(1, 0), (7, 0), (12, 3), (30, 11), (9, 8)])
def test_a_band_matrix_holds_multiplies_and_stores_for_lapack_what_the_dense_one_does(
    size, bandwidth
):
    rng = np.random.default_rng(size + bandwidth)
    rows, columns, values, dense = _random_band(rng, size, bandwidth)
    band = BandMatrix.of_blocks(rows, columns, values.reshape(-1, 1, 1), size, bandwidth)
    np.testing.assert_allclose(band.toarray(), dense, rtol=0, atol=1e-12)
    x = rng.normal(size=size)
    np.testing.assert_allclose(band @ x, dense @ x, rtol=0, atol=1e-12)
    lower = band.lower()
    for k in range(bandwidth + 1):
        np.testing.assert_allclose(lower[k, : size - k], np.diagonal(dense, -k), atol=1e-12)
        assert not lower[k, size - k :].any()
    at = np.sort(rng.choice(size, min(size, bandwidth + 1), replace=False))
    at = at[at - at[0] <= bandwidth]
    block = rng.normal(size=(at.size, at.size))
    block += block.T
    band.add(at, block)
    dense[np.ix_(at, at)] += block
    np.testing.assert_allclose(band.toarray(), dense, rtol=0, atol=1e-12)


def test_windows_held_as_band_matrices_end_where_dense_windows_end(monkeypatch):
    """An SE3 visual-odometry stream (measurements reaching 4 poses back) with a window of 40
    poses, whose H is a band matrix (bandwidth 29 of 240 unknowns): the same estimates after
    every call, within 1e-9, as with every window held dense."""
    full, _ = visual_odometry(SE3, 80, reach=4, seed=3)

    def streamed() -> tuple[list[np.ndarray], set[str]]:
        graph = PoseGraph(SE3)
        smoother = Smoother(graph, lag=40)
        ends = np.maximum(full.edges.i, full.edges.j)
        estimates, storages = [], set()
        for k in range(full.num_nodes):
            graph.add_node(k, full.values[0] if k == 0 else None)
            if k == 0:
                graph.add_priors([0], full.priors.measurements, full.priors.information)
            arriving = np.flatnonzero(ends == k)
            e = full.edges
            graph.add_edges(
                e.i[arriving], e.j[arriving], e.measurements[arriving], e.information[arriving]
            )
            storages.add(smoother.optimize().summary.linear_solver)
            estimates.append(graph.values.as_matrix()[max(0, k - 39) : k + 1])
        return estimates, storages

    band, band_storages = streamed()
    monkeypatch.setattr(marginal, "storage", lambda size, bandwidth: "dense")
    dense, dense_storages = streamed()
    assert "band" in band_storages and dense_storages == {"dense"}
    for ours, theirs in zip(band, dense, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)


@pytest.mark.parametrize("d", [2, 3, 6])
def test_blocks_summed_into_a_band_matrix_are_where_a_dense_sum_puts_them(d):
    """(d, d) blocks at block rows and columns up to 2 apart, some repeated, both triangles:
    the band matrix of bandwidth 3d − 1 holds the dense sum."""
    rng = np.random.default_rng(d)
    n = 9
    r, c = np.indices((n, n))
    near = np.abs(r - c) <= 2
    rows, columns = r[near], c[near]
    repeat = rng.integers(0, rows.size, 10)
    rows, columns = np.concatenate([rows, rows[repeat]]), np.concatenate([columns, columns[repeat]])
    blocks = rng.normal(size=(rows.size, d, d))
    dense = np.zeros((n * d, n * d))
    for row, column, block in zip(rows, columns, blocks, strict=True):
        dense[row * d : (row + 1) * d, column * d : (column + 1) * d] += block
    band = BandMatrix.of_blocks(rows, columns, blocks, n * d, 3 * d - 1)
    np.testing.assert_allclose(band.toarray(), dense, rtol=0, atol=1e-12)
