"""The information checks' batched definiteness test, ranks and refusals against each matrix's
eigenvalues."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph.checks import information_problems, information_ranks, positive_definite


def _spectra(count: int, d: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric matrices of known eigenvalues, one in four each: definite, semi-definite with
    zero or 1e-12-relative eigenvalues (an unmeasured direction), clearly indefinite, or at the
    scale of a g2o file's information (1e4)."""
    rng = np.random.default_rng(seed)
    rotations, _ = np.linalg.qr(rng.normal(size=(count, d, d)))
    eigenvalues = rng.uniform(0.1, 10.0, size=(count, d))
    eigenvalues[1::4, 0] = rng.choice([0.0, 1e-12], size=len(eigenvalues[1::4]))
    eigenvalues[2::4, 0] = -rng.uniform(0.1, 1.0, size=len(eigenvalues[2::4]))
    eigenvalues[3::4] *= 1e4
    matrices = rotations @ (eigenvalues[:, :, None] * np.swapaxes(rotations, 1, 2))
    return 0.5 * (matrices + np.swapaxes(matrices, 1, 2)), eigenvalues


@pytest.mark.parametrize("d", [3, 6, 7])
def test_positive_definite_is_every_eigenvalue_positive(d):
    matrices, eigenvalues = _spectra(400, d, seed=d)
    clear = (eigenvalues.min(axis=1) > 1e-6) | (eigenvalues.min(axis=1) < 0)
    np.testing.assert_array_equal(
        positive_definite(matrices)[clear], (eigenvalues.min(axis=1) > 0)[clear]
    )
    assert not positive_definite(np.zeros((1, d, d)))[0]
    assert positive_definite(matrices[::4]).all()  # every one definite: numpy's Cholesky says so


@pytest.mark.parametrize("d", [3, 6])
def test_ranks_and_refusals_are_those_of_the_eigenvalues(d):
    matrices, _ = _spectra(400, d, seed=10 + d)
    matrices = np.concatenate([matrices, np.zeros((1, d, d))])
    eigenvalues = np.linalg.eigvalsh(matrices)
    size = np.abs(matrices).max(axis=(1, 2))
    expected_ranks = np.count_nonzero(eigenvalues > 1e-9 * eigenvalues[:, -1:], axis=1)
    np.testing.assert_array_equal(information_ranks(matrices), expected_ranks)
    refused, why = information_problems(matrices)
    expected = (eigenvalues[:, 0] < -1e-9 * size) | (size == 0)
    np.testing.assert_array_equal(refused, expected)
    negative = int(np.flatnonzero(eigenvalues[:, 0] < -0.05)[0])
    assert why(negative) == f"not positive semi-definite (λ_min = {eigenvalues[negative, 0]:.3g})"
    assert why(len(matrices) - 1) == "zero (it would weigh nothing)"


@pytest.mark.filterwarnings("error")
def test_definiteness_holds_at_any_scale_without_warnings():
    overflowing = np.array([[1e-300, 1e300, 0.0], [1e300, 1.0, 0.0], [0.0, 0.0, 1.0]])
    matrices = np.array([np.eye(3) * 1e300, overflowing, np.eye(3) * 1e-300, np.zeros((3, 3))])
    np.testing.assert_array_equal(positive_definite(matrices), [True, False, True, False])
