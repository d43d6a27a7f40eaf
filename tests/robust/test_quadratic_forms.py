"""The deleted residuals' and innovations' quadratic forms, by a solve where Bₑ is well
conditioned and from its eigenvalues elsewhere, against the clipped eigendecomposition; and the
whitening of edges, by Cholesky where their information is definite."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.robust.leverage import SMALLEST_COMPLEMENT, _quadratic_forms, _whitening


def _matrices(count: int, d: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric matrices with known spectra, a third of them with an eigenvalue below
    ``SMALLEST_COMPLEMENT`` (an edge that nothing else measures in some direction), plus an
    antisymmetric part that the forms must ignore; and whitened residuals."""
    rng = np.random.default_rng(seed)
    rotations, _ = np.linalg.qr(rng.normal(size=(count, d, d)))
    eigenvalues = rng.uniform(0.01, 2.0, size=(count, d))
    eigenvalues[::3, 0] = rng.choice([0.0, 1e-9, 1e-5, 5e-4], size=len(eigenvalues[::3]))
    matrices = rotations @ (eigenvalues[:, :, None] * np.swapaxes(rotations, 1, 2))
    skew = rng.normal(size=(count, d, d))
    return matrices + 1e-3 * (skew - np.swapaxes(skew, 1, 2)), rng.normal(size=(count, d))


def _reference(whitened: np.ndarray, matrices: np.ndarray) -> tuple[np.ndarray, ...]:
    """From the eigendecomposition of the symmetrised matrices, eigenvalues clipped."""
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (matrices + np.swapaxes(matrices, 1, 2)))
    clipped = eigenvalues.clip(min=SMALLEST_COMPLEMENT)
    projected = np.einsum("mba,mb->ma", eigenvectors, whitened)
    return (
        (projected**2 / clipped).sum(axis=1),
        (projected**2 / clipped**2).sum(axis=1),
        (clipped * (clipped > SMALLEST_COMPLEMENT)).sum(axis=1),
    )


@pytest.mark.parametrize("d", [3, 6, 7])
def test_forms_equal_the_clipped_eigendecomposition(d):
    matrices, whitened = _matrices(300, d, seed=d)
    computed = _quadratic_forms(whitened, matrices)
    for got, expected in zip(computed, _reference(whitened, matrices), strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-9)
    # Both ways were taken: some redundancy sums drop a clipped eigenvalue, most are traces.
    traces = np.trace(matrices, axis1=1, axis2=2)
    dropped = ~np.isclose(computed[2], traces, rtol=1e-12)
    assert 0 < dropped.sum() < len(matrices) / 2


def test_an_overflowed_edge_gets_infinite_forms_and_full_redundancy():
    matrices, whitened = _matrices(6, 6, seed=1)
    whitened[1, 2] = np.inf
    matrices[4, 0, 3] = np.nan
    inverse, squares, redundancy = _quadratic_forms(whitened, matrices)
    assert np.isinf(inverse[[1, 4]]).all() and np.isinf(squares[[1, 4]]).all()
    assert np.all(redundancy[[1, 4]] == 6)
    assert np.isfinite(inverse[[0, 2, 3, 5]]).all()


def test_whitening_squares_to_the_information_definite_or_not():
    """Wᵀ W = Ω for definite information, nearly singular information (an eigenvalue 1e-17 of
    the others, where a Cholesky may fail), and a position-only one, in one batch."""
    matrices, _ = _matrices(30, 6, seed=5)
    information = np.concatenate(
        [
            0.5 * (matrices[1::3] + np.swapaxes(matrices[1::3], 1, 2)) + 3 * np.eye(6),
            np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 1e-17])[None],
            np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])[None],
        ]
    )
    roots = _whitening(information)
    np.testing.assert_allclose(np.swapaxes(roots, 1, 2) @ roots, information, atol=1e-12)
