"""Repair of information matrices that are not positive semi-definite, or of every one into
SE-Sync's isotropic model (Rosen et al. 2019, §5 and its ``read_g2o_file``)."""

from __future__ import annotations

import numpy as np

from ..lie import LieGroup
from .checks import information_problems

REPAIRS = ("psd", "isotropic")

EIGENVALUE_FLOOR = 1e-6
"""Eigenvalues are clipped at this share of a matrix's largest: the nearest positive
semi-definite matrix (Higham 1988) clips at 0; the floor keeps every direction weighed a little,
as a measurement that states a direction at all did."""


def clipped(matrices: np.ndarray) -> np.ndarray:
    """Symmetric (…, d, d) matrices with their eigenvalues clipped at ``EIGENVALUE_FLOOR`` of
    the largest (0 where the largest is not positive)."""
    symmetric = 0.5 * (matrices + np.swapaxes(matrices, -1, -2))
    eigenvalues, vectors = np.linalg.eigh(symmetric)
    floor = EIGENVALUE_FLOOR * np.maximum(eigenvalues[..., -1:], 0.0)
    eigenvalues = np.maximum(eigenvalues, floor)
    return np.einsum("...ij,...j,...kj->...ik", vectors, eigenvalues, vectors)


def _isotropic_precision(block: np.ndarray) -> np.ndarray:
    """d / tr(B⁻¹) of (…, d, d) blocks, those not positive definite ``clipped`` first: the
    precision of the isotropic Gaussian nearest in information divergence, as SE-Sync takes τ
    and κ (of a positive definite block exactly SE-Sync's value); 0 for a block that weighs
    nothing."""
    size = block.shape[-1]
    definite = np.linalg.eigvalsh(0.5 * (block + np.swapaxes(block, -1, -2)))[..., 0] > 0
    safe = np.where(definite[..., None, None], block, clipped(block))
    positive = np.linalg.eigvalsh(safe)[..., 0] > 0
    precision = np.zeros(block.shape[:-2])
    precision[positive] = size / np.trace(np.linalg.inv(safe[positive]), axis1=-2, axis2=-1)
    return precision


def tangent_blocks(group: type[LieGroup]) -> list[slice]:
    """The tangent's blocks in the order of CONVENTIONS.md: translation, rotation, and the rest
    (Sim3's log-scale)."""
    translation = group.point_dim
    rotation = translation + translation * (translation - 1) // 2
    blocks = [slice(0, translation), slice(translation, rotation)]
    return blocks + ([slice(rotation, group.dof)] if rotation < group.dof else [])


def repair_information(
    information: np.ndarray, group: type[LieGroup], mode: str
) -> tuple[np.ndarray, np.ndarray]:
    """(repaired (k, d, d) information, mask of the matrices changed). "psd": each matrix that
    ``information_problems`` refuses for an eigenvalue below zero (or asymmetry) is clipped to
    a positive semi-definite one (``clipped``); others are kept. "isotropic": every matrix
    becomes SE-Sync's model, one precision per block (translation τ, rotation κ, log-scale),
    d / tr(B⁻¹) of its diagonal block, cross terms dropped."""
    if mode not in REPAIRS:
        raise ValueError(f"an information repair is one of {', '.join(REPAIRS)}, not {mode!r}")
    information = np.asarray(information, float)
    if mode == "psd":
        bad, _ = information_problems(information)
        finite = np.isfinite(information).all(axis=(1, 2))
        change = bad & finite & (np.abs(information).max(axis=(1, 2)) > 0)
        repaired = information.copy()
        repaired[change] = clipped(information[change])
        return repaired, change
    repaired = np.zeros_like(information)
    for block in tangent_blocks(group):
        size = block.stop - block.start
        precision = _isotropic_precision(information[:, block, block])
        repaired[:, block, block] = precision[:, None, None] * np.eye(size)
    return repaired, np.ones(len(information), dtype=bool)
