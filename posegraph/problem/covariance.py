"""Joint covariance blocks of groups of nodes from factorised normal equations: blocks of H⁻¹
over the free nodes' tangents, zero for held nodes (the gauge)."""

from __future__ import annotations

import numpy as np

from .linear import NormalEquations


def joint_covariances(system: NormalEquations, groups: np.ndarray) -> np.ndarray:
    """The joint covariances, (G, k·d, k·d), of G groups of k node indices (G, k), from
    ``system`` factorised for the covariance of these groups (``covariance_of``); rows and
    columns of held nodes are zero."""
    d = system.dof
    count, k = groups.shape
    blocks = system.block_of[groups]
    free = np.repeat(blocks >= 0, d, axis=1)
    covariances = np.zeros((count, k * d, k * d))
    if not free.any():
        return covariances
    columns = (blocks[:, :, None] * d + np.arange(d)).reshape(count, k * d)
    # A held node's columns stand in for a free column of its group (else the first), then
    # their rows and columns are zeroed.
    stand_in = np.where(free.any(axis=1), columns[np.arange(count), free.argmax(axis=1)], 0)
    columns = np.where(free, columns, stand_in[:, None])
    covariances = system.cholesky.covariance_blocks(columns)
    # Solves leave an asymmetry of order cond(H)·ε (with SuperLU, up to 1e-7 of a block's
    # largest entry where the block's condition number was 1e9 to 1e11); the mean of the
    # block and its transpose is symmetric, as a covariance is.
    covariances = 0.5 * (covariances + np.swapaxes(covariances, 1, 2))
    return covariances * (free[:, :, None] & free[:, None, :])
