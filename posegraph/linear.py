"""The normal equations H δ = −g of a pose graph on a sparsity pattern fixed once.

``H = Σ Jᵀ Ω J`` and ``g = Σ Jᵀ Ω r`` over the free (not fixed) nodes. ``NormalEquations``
computes, once, the CSC pattern of H (both triangles, d × d blocks: one per free node and one
per pair of free nodes joined by an edge) and, for every edge block, where its d² entries land in
the CSC ``data`` array. Each iteration then fills ``data`` with a single ``np.bincount``; no
Python loop runs over edges. Fixed nodes are eliminated: their blocks are never formed.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from .factors import Linearization
from .graph import PoseGraph
from .sparse_cholesky import make_cholesky


class NormalEquations:
    """Pattern, assembly and factorisation of H for one graph structure."""

    def __init__(self, graph: PoseGraph, held: np.ndarray, backend: str = "auto") -> None:
        d = graph.group.dof
        n = graph.num_nodes
        free = np.ones(n, dtype=bool)
        free[held] = False
        self.dof = d
        self.free_nodes = np.flatnonzero(free)
        self.block_of = np.full(n, -1, dtype=np.int64)
        self.block_of[self.free_nodes] = np.arange(self.free_nodes.size)
        self.size = self.free_nodes.size * d

        a, b = self.block_of[graph.edges.i], self.block_of[graph.edges.j]
        both = (a >= 0) & (b >= 0)
        num_blocks = max(self.free_nodes.size, 1)
        # Block keys col·B + row, sorted: the order of blocks in CSC (by column, then row).
        low, high = np.minimum(a[both], b[both]), np.maximum(a[both], b[both])
        diagonal = np.arange(self.free_nodes.size)
        block_keys = np.unique(
            np.concatenate(
                [diagonal * (num_blocks + 1), high * num_blocks + low, low * num_blocks + high]
            )
        )
        block_cols, block_rows = np.divmod(block_keys, num_blocks)
        blocks_per_col = np.bincount(block_cols, minlength=self.free_nodes.size)
        first_block_of_col = np.concatenate([[0], np.cumsum(blocks_per_col)[:-1]])
        rank_in_col = np.arange(block_keys.size) - first_block_of_col[block_cols]
        self.indptr = np.concatenate([[0], np.cumsum(np.repeat(blocks_per_col * d, d))])
        within = np.arange(d)
        # Entry (p, q) of block k sits in scalar column c·d + q, after rank_in_col·d entries.
        block_positions = (
            self.indptr[(block_cols * d)[:, None, None] + within[None, None, :]]
            + (rank_in_col * d)[:, None, None]
            + within[None, :, None]
        ).reshape(-1, d * d)
        self.indices = np.empty(self.indptr[-1], dtype=np.int64)
        self.indices[block_positions] = (
            (block_rows * d)[:, None, None] + within[None, :, None] + 0 * within[None, None, :]
        ).reshape(-1, d * d)
        self.diagonal_positions = block_positions[
            np.searchsorted(block_keys, diagonal * (num_blocks + 1))
        ][:, within * d + within].ravel()

        # Every edge block has a place: its d² positions in ``data``, or the trash slot ``nnz``
        # (dropped after the sum) when a node it touches is held.
        trash = self.indptr[-1]
        held_block = np.full((1, d * d), trash)

        def positions(r: np.ndarray, c: np.ndarray) -> np.ndarray:
            valid = (r >= 0) & (c >= 0)
            found = np.searchsorted(block_keys, np.where(valid, c * num_blocks + r, 0))
            return np.where(
                valid[:, None], block_positions[np.minimum(found, block_keys.size - 1)], held_block
            )

        p = self.block_of[graph.priors.i]
        self._hessian_positions = np.concatenate(
            [positions(a, a), positions(b, b), positions(a, b), positions(b, a), positions(p, p)]
        ).ravel()

        def gradient_positions(blocks: np.ndarray) -> np.ndarray:
            index = blocks[:, None] * d + within
            return np.where(blocks[:, None] >= 0, index, self.size).ravel()

        self._gradient_positions = np.concatenate(
            [gradient_positions(a), gradient_positions(b), gradient_positions(p)]
        )
        self.cholesky = make_cholesky(self.indices, self.indptr, self.size, backend)

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    def assemble(
        self,
        between: Linearization,
        between_information: np.ndarray,
        priors: Linearization,
        prior_information: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The CSC ``data`` of H and the gradient g, from the edges' Jacobians.

        Block products are written into one buffer in the order of the precomputed positions
        (H_ii, H_jj, H_ij, H_ji, then priors) and summed into place by one ``np.bincount``.
        """
        m, p, d = between.residuals.shape[0], priors.residuals.shape[0], self.dof
        jit_omega = np.swapaxes(between.jac_i, 1, 2) @ between_information
        jjt_omega = np.swapaxes(between.jac_j, 1, 2) @ between_information
        jpt_omega = np.swapaxes(priors.jac_j, 1, 2) @ prior_information
        blocks = np.empty((4 * m + p, d, d))
        np.matmul(jit_omega, between.jac_i, out=blocks[:m])
        np.matmul(jjt_omega, between.jac_j, out=blocks[m : 2 * m])
        np.matmul(jit_omega, between.jac_j, out=blocks[2 * m : 3 * m])
        blocks[3 * m : 4 * m] = np.swapaxes(blocks[2 * m : 3 * m], 1, 2)
        np.matmul(jpt_omega, priors.jac_j, out=blocks[4 * m :])
        data = np.bincount(self._hessian_positions, blocks.reshape(-1), self.nnz + 1)[:-1]

        pieces = np.empty((2 * m + p, d))
        np.matmul(jit_omega, between.residuals[:, :, None], out=pieces[:m, :, None])
        np.matmul(jjt_omega, between.residuals[:, :, None], out=pieces[m : 2 * m, :, None])
        np.matmul(jpt_omega, priors.residuals[:, :, None], out=pieces[2 * m :, :, None])
        gradient = np.bincount(self._gradient_positions, pieces.reshape(-1), self.size + 1)[:-1]
        return data, gradient

    def diagonal(self, data: np.ndarray) -> np.ndarray:
        """diag(H) from its CSC data."""
        return data[self.diagonal_positions]

    def factorize(self, data: np.ndarray, damping: np.ndarray | None = None) -> None:
        """Factorise H + diag(damping); raises ``NotPositiveDefinite`` on failure."""
        if damping is not None:
            data = data.copy()
            data[self.diagonal_positions] += damping
        self.cholesky.factorize(data)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation."""
        return self.cholesky.solve(rhs)

    def matrix(self, data: np.ndarray) -> scipy.sparse.csc_matrix:
        """H as a scipy matrix (for inspection and tests)."""
        return scipy.sparse.csc_matrix((data, self.indices, self.indptr), (self.size, self.size))

    def scatter(self, step: np.ndarray, num_nodes: int) -> np.ndarray:
        """A (num_nodes, d) tangent step with zeros on the held nodes."""
        full = np.zeros((num_nodes, self.dof))
        full[self.free_nodes] = step.reshape(-1, self.dof)
        return full
