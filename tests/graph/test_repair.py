"""Repair of information matrices: clipping to positive semi-definite, and SE-Sync's isotropic
model (one precision per block, d / tr(B⁻¹) of the diagonal block)."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph.checks import information_problems
from posegraph.graph.repair import EIGENVALUE_FLOOR, repair_information
from posegraph.lie import SE2, SE3, Sim3

# cubicle.g2o's kind of matrix: the (z, qx, qy) block couples translation and rotation far
# beyond what the diagonal allows.
INDEFINITE = np.diag([100.0, 100.0, 10.0, 10.0, 10.0, 400.0])
INDEFINITE[2, 3] = INDEFINITE[3, 2] = 84022.0
INDEFINITE[2, 4] = INDEFINITE[4, 2] = 132748.0


def test_psd_clips_only_the_matrices_refused():
    good = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    repaired, changed = repair_information(np.stack([good, INDEFINITE]), SE3, "psd")
    assert changed.tolist() == [False, True]
    np.testing.assert_array_equal(repaired[0], good)
    assert not information_problems(repaired)[0].any()
    eigenvalues = np.linalg.eigvalsh(repaired[1])
    assert eigenvalues.min() == pytest.approx(EIGENVALUE_FLOOR * eigenvalues.max(), rel=1e-6)
    # The eigenvectors are kept and the positive eigenvalues too (Higham's nearest, floored).
    original = np.linalg.eigvalsh(INDEFINITE)
    np.testing.assert_allclose(eigenvalues[original > 0], original[original > 0], rtol=1e-9)


def test_isotropic_is_one_precision_per_block():
    """SE3: τ = 3 / tr(Ω_ρρ⁻¹), κ = 3 / tr(Ω_φφ⁻¹), cross terms dropped (SE-Sync's
    ``read_g2o_file``, over posegraph's φ); Sim3 keeps its log-scale; SE2's rotation is 1 × 1."""
    information = np.diag([1.0, 4.0, 4.0, 2.0, 2.0, 8.0])
    information[0, 3] = information[3, 0] = 0.5
    repaired, changed = repair_information(information[None], SE3, "isotropic")
    tau, kappa = 3 / (1 + 0.25 + 0.25), 3 / (0.5 + 0.5 + 0.125)
    np.testing.assert_allclose(repaired[0], np.diag([tau] * 3 + [kappa] * 3), rtol=1e-12)
    assert changed.all()
    sim3 = np.diag([1.0, 4.0, 4.0, 2.0, 2.0, 8.0, 50.0])
    np.testing.assert_allclose(
        repair_information(sim3[None], Sim3, "isotropic")[0][0],
        np.diag([tau] * 3 + [kappa] * 3 + [50.0]),
        rtol=1e-12,
    )
    se2 = np.array([[4.0, 1.0, 0.5], [1.0, 9.0, 2.0], [0.5, 2.0, 16.0]])
    expected = 2 / np.trace(np.linalg.inv(se2[:2, :2]))
    np.testing.assert_allclose(
        repair_information(se2[None], SE2, "isotropic")[0][0],
        np.diag([expected, expected, 16.0]),
        rtol=1e-12,
    )


def test_an_indefinite_block_is_made_positive_before_its_precision():
    repaired, _ = repair_information(INDEFINITE[None], SE3, "isotropic")
    assert not information_problems(repaired)[0].any()
    assert np.all(np.diag(repaired[0]) > 0)


def test_a_positive_definite_block_keeps_se_syncs_precision_however_thin():
    """cubicle.g2o's translation blocks: eigenvalues 10 and 1.7e7, positive definite; the
    precision is SE-Sync's 3 / tr(B⁻¹), not that of a block clipped at the floor."""
    information = np.diag([1.0, 1.0, 1.0, 4.0, 4.0, 4.0])
    information[:3, :3] = [[2.46483e6, 5.35530e6, 0.0], [5.35530e6, 1.52034e7, 0.0], [0, 0, 10.0]]
    repaired, _ = repair_information(information[None], SE3, "isotropic")
    assert repaired[0, 0, 0] == pytest.approx(3 / np.trace(np.linalg.inv(information[:3, :3])))
    assert repaired[0, 0, 0] == pytest.approx(29.9994, rel=1e-5)


def test_an_unknown_repair_is_refused():
    with pytest.raises(ValueError, match="one of psd, isotropic, not 'clip'"):
        repair_information(INDEFINITE[None], SE3, "clip")
