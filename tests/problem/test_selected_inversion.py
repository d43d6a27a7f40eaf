"""Selected inversion against a dense inverse: on a factor built here from numpy's Cholesky, and
on CHOLMOD's supernodal factor (relaxed supernodes, explicit zeros) behind covariances."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import threadpoolctl

from posegraph.problem import selected_inversion
from posegraph.problem.backends import available_backends, make_cholesky
from posegraph.problem.selected_inversion import (
    TRIANGULAR_LEAF,
    SupernodalFactor,
    _gram_of_lower,
    _lower_times,
    _times_lower,
    _triangular_inverse,
    inverse_blocks,
    selected_inverse,
)


def _sparse_spd(size: int, seed: int) -> np.ndarray:
    """A dense SPD matrix with a sparse pattern: a chain with random long-range couplings,
    in 3 × 3 blocks, like a pose graph's information matrix. The chain's even nodes come
    first, so that its elimination tree branches."""
    rng = np.random.default_rng(seed)
    nodes = size // 3
    place = np.argsort(np.r_[0:nodes:2, 1:nodes:2])
    pairs = [(place[k], place[k + 1]) for k in range(nodes - 1)]
    pairs += [tuple(sorted(rng.choice(nodes, 2, replace=False))) for _ in range(nodes // 3)]
    matrix = np.zeros((size, size))
    for a, b in pairs:
        rows = np.r_[3 * a : 3 * a + 3, 3 * b : 3 * b + 3]
        root = rng.normal(size=(6, 6))
        matrix[np.ix_(rows, rows)] += root @ root.T
    return matrix + np.eye(size)


def _factor(matrix: np.ndarray) -> SupernodalFactor:
    """numpy's dense Cholesky factor, kept where it is not zero (the fill pattern)."""
    lower = scipy.sparse.csc_matrix(np.linalg.cholesky(matrix))
    lower.sort_indices()
    return SupernodalFactor(lower.indptr, lower.indices, lower.data)


def _assert_inverse_in_pattern(matrix: np.ndarray, factor: SupernodalFactor, rtol: float) -> None:
    """Selected inversion of every column equals the dense inverse in every supernode."""
    inverse = np.linalg.inv(matrix)
    computed = selected_inverse(factor, np.arange(matrix.shape[0]))
    for s in range(factor.first.size):
        columns = np.arange(factor.first[s], factor.first[s] + factor.width[s])
        expected = inverse[np.ix_(factor.rows(s), columns)]
        np.testing.assert_allclose(computed.block(s), expected, rtol=rtol, atol=1e-13)


def test_selected_inverse_is_the_inverse_in_the_factors_pattern():
    matrix = _sparse_spd(90, seed=1)
    factor = _factor(matrix)
    assert factor.width.max() > 1 and factor.first.size > 5  # supernodes, and several
    _assert_inverse_in_pattern(matrix, factor, rtol=1e-10)


def test_selected_inversion_runs_blas_on_one_thread(monkeypatch):
    """numpy's OpenBLAS crashed on two threads in the products of a factor with a 16,389-column
    front (w10000 with 30% false loops); selected inversion limits BLAS to one thread, and
    gives it back its threads after."""
    seen = []
    inner = selected_inversion._selected_inverse

    def recording(factor, columns):
        seen.append(_blas_threads())
        return inner(factor, columns)

    monkeypatch.setattr(selected_inversion, "_selected_inverse", recording)
    before = _blas_threads()
    matrix = _sparse_spd(30, seed=2)
    _assert_inverse_in_pattern(matrix, _factor(matrix), rtol=1e-10)
    assert seen and all(threads == 1 for threads in seen[0]) and seen[0]
    assert _blas_threads() == before


def _blas_threads() -> list[int]:
    """The threads of each BLAS library loaded."""
    pools = threadpoolctl.threadpool_info()
    return [pool["num_threads"] for pool in pools if pool["user_api"] == "blas"]


@pytest.mark.parametrize(
    "width", [1, TRIANGULAR_LEAF, TRIANGULAR_LEAF + 1, 3 * TRIANGULAR_LEAF + 7]
)
def test_triangular_inverse_by_halves_is_the_inverse(width):
    """Stacked lower-triangular matrices, as wide as numpy's LU inverse takes them and wider
    (by halves, twice): their inverses, lower-triangular."""
    rng = np.random.default_rng(width)
    lower = np.tril(rng.normal(size=(3, width, width))) + 2 * width * np.eye(width)
    inverse = _triangular_inverse(lower)
    np.testing.assert_allclose(
        inverse @ lower, np.broadcast_to(np.eye(width), lower.shape), atol=1e-13
    )
    assert np.all(np.triu(inverse, 1) == 0)


@pytest.mark.parametrize("width", [TRIANGULAR_LEAF, TRIANGULAR_LEAF + 1, 3 * TRIANGULAR_LEAF + 7])
def test_products_with_a_triangle_by_halves_are_the_products(width):
    """L X, X L and Lᵀ L for stacked lower-triangular L, as wide as one product takes them and
    wider (by halves, twice), equal the products of the full matrices."""
    rng = np.random.default_rng(width)
    lower = np.tril(rng.normal(size=(2, width, width)))
    right, left = rng.normal(size=(2, width, 5)), rng.normal(size=(2, 7, width))
    np.testing.assert_allclose(_lower_times(lower, right), lower @ right, atol=1e-12)
    np.testing.assert_allclose(_times_lower(left, lower), left @ lower, atol=1e-12)
    gram = np.swapaxes(lower, 1, 2) @ lower
    np.testing.assert_allclose(_gram_of_lower(lower), gram, atol=1e-12)


def test_a_wide_supernode_and_many_narrow_ones():
    """A graph whose last 70 nodes are all coupled (a root supernode wider than
    ``TRIANGULAR_LEAF``) and a long chain (many narrow supernodes of one shape, written by one
    scatter): the inverse in the factor's pattern."""
    matrix = _sparse_spd(600, seed=4)
    coupled = np.arange(390, 600)
    rng = np.random.default_rng(4)
    root = rng.normal(size=(coupled.size, coupled.size))
    matrix[np.ix_(coupled, coupled)] += root @ root.T / coupled.size
    factor = _factor(matrix)
    assert factor.width.max() > TRIANGULAR_LEAF
    _assert_inverse_in_pattern(matrix, factor, rtol=1e-9)


def test_blocks_of_chosen_columns_need_only_their_paths_to_the_root():
    matrix = _sparse_spd(120, seed=2)
    factor = _factor(matrix)
    inverse = np.linalg.inv(matrix)
    lower = np.linalg.cholesky(matrix)
    far = np.argwhere(lower != 0)
    far_row, far_column = far[far[:, 0] - far[:, 1] > 20][0]  # a long-range entry of L
    for groups in (np.array([[3, 4, 5], [0, 1, 2]]), np.array([[far_column, far_row]]), [[40]]):
        groups = np.asarray(groups)
        for group, block in zip(groups, inverse_blocks(factor, groups), strict=True):
            expected = inverse[np.ix_(group, group)]
            np.testing.assert_allclose(block, expected, rtol=1e-10, atol=1e-13)
    assert factor.path_to_root(np.array([0])).size < factor.first.size / 2  # not the whole tree
    outside = np.argwhere(np.tril(lower) == 0)
    row, column = outside[outside[:, 0] > outside[:, 1]][0]
    with pytest.raises(ValueError, match=rf"entry \({row}, {column}\) is outside"):
        inverse_blocks(factor, np.array([[column, row]]))


@pytest.mark.skipif("cholmod" not in available_backends(), reason="cvxopt is not installed")
def test_cholmod_covariance_blocks_by_selected_inversion_then_factorize_again():
    """More columns than ``SOLVED_COLUMNS``: CHOLMOD's factor is read out and inverted; the
    factoriser then factorises and solves another matrix of the pattern as before."""
    matrix = _sparse_spd(300, seed=3)
    pattern = scipy.sparse.csc_matrix(matrix)
    pattern.sort_indices()
    cholesky = make_cholesky(pattern.indices, pattern.indptr, 300, "cholmod", for_covariance=True)
    cholesky.factorize(pattern.data)
    inverse = np.linalg.inv(matrix)
    groups = np.arange(300).reshape(100, 3)
    for group, block in zip(groups, cholesky.covariance_blocks(groups), strict=True):
        np.testing.assert_allclose(block, inverse[np.ix_(group, group)], rtol=1e-9, atol=1e-12)
    cholesky.factorize(2.0 * pattern.data)
    rhs = np.arange(300.0)
    np.testing.assert_allclose(cholesky.solve(rhs), np.linalg.solve(2.0 * matrix, rhs), rtol=1e-9)
