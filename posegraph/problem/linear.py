"""Block-sparse symmetric systems factorised on a layout fixed once (``pattern.BlockLayout``),
and the normal equations H δ = −g of a pose graph built on them.

``BlockPattern`` adds to the layout its Cholesky factoriser, whose symbolic factorisation is
computed once (grown from the last one's where the layout grew). ``NormalEquations`` uses it
with d = dof for ``H = Σ Jᵀ Ω J`` and ``g = Σ Jᵀ Ω r``; the chordal initialisation uses it with
d = 2 or 3 for its linear systems.
"""

from __future__ import annotations

import copy

import numpy as np

from ..graph import PoseGraph
from .backends import make_cholesky
from .cholesky import NotPositiveDefinite
from .factors import Linearization
from .pattern import BlockLayout, free_block_index

RIDGES = (1e-12, 1e-9, 1e-6)
"""Relative ridges ε (H + ε diag(H)) that ``factorize_regularized`` tries, smallest first."""


class BlockPattern(BlockLayout):
    """A block layout (``BlockLayout``) with its factoriser.

    ``covariance_of``: (G, k) groups of nodes whose joint covariance will be read. The
    factorisation is prepared for ``covariance_blocks``, and the blocks between the nodes of
    each group join the pattern (as zeros where no edge fills them), which puts them in the
    factor's pattern.
    """

    def __init__(
        self,
        block_of: np.ndarray,
        edge_i: np.ndarray,
        edge_j: np.ndarray,
        prior_i: np.ndarray,
        d: int,
        backend: str = "auto",
        covariance_of: np.ndarray | None = None,
        previous: BlockPattern | None = None,
    ) -> None:
        coupled = None if covariance_of is None else _pairs_within(covariance_of)
        super().__init__(block_of, edge_i, edge_j, prior_i, d, coupled, previous)
        self.cholesky = make_cholesky(
            self.indices,
            self.indptr,
            self.size,
            backend,
            covariance_of is not None,
            previous.cholesky if self.grown else None,
            self.appended,
            self.diagonal_blocks(),
        )

    def factorize(self, data: np.ndarray, damping: np.ndarray | None = None) -> None:
        """Factorise the matrix plus diag(damping); raises ``NotPositiveDefinite`` on failure.
        An empty matrix (every node held) has nothing to factorise."""
        if self.size == 0:
            return
        if damping is not None:
            data = data.copy()
            data[self.diagonal_positions] += damping
        self.cholesky.factorize(data)

    def factorize_regularized(self, data: np.ndarray) -> float:
        """Factorise the matrix, or if it is not numerically positive definite (weights of
        extreme range, or directions that nothing measures), the matrix plus the smallest ridge
        ε ``ridge_scale``, ε in ``RIDGES``, that is; returns ε (0.0 if none was needed). For
        systems whose solution is an estimate (initial values, leverage), where the ridge's
        change does not matter; raises ``NotPositiveDefinite`` if no ridge helps."""
        try:
            self.factorize(data)
            return 0.0
        except NotPositiveDefinite:
            scale = self.ridge_scale(data)
        for ridge in RIDGES:
            try:
                self.factorize(data, ridge * scale)
                return ridge
            except NotPositiveDefinite:
                continue
        raise NotPositiveDefinite(
            f"not numerically positive definite, even with a ridge of {RIDGES[-1]:g} diag(H)"
        )

    def ridge_scale(self, data: np.ndarray) -> np.ndarray:
        """diag(H), where a zero (a direction that nothing measures: its row and column are
        zero, H being positive semi-definite) takes H's largest diagonal entry, so that a
        ridge's solution is zero along it."""
        diagonal = self.diagonal(data)
        largest = float(diagonal.max(initial=0.0))
        return np.where(diagonal == 0, largest if 0 < largest < np.inf else 1.0, diagonal)

    def pivot_shares(self, data: np.ndarray) -> np.ndarray:
        """Per column, its pivot in the last factorisation over its entry of ``ridge_scale``
        (of ``data``, the matrix factorised before any ridge): near zero where the columns
        eliminated before it nearly span it (``cholesky``)."""
        return self.cholesky.pivots() / self.ridge_scale(data)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation (an empty system's solution is empty)."""
        if self.size == 0:
            return np.zeros_like(rhs)
        return self.cholesky.solve(rhs)


def _pairs_within(groups: np.ndarray) -> np.ndarray:
    """(2, m) node indices: every pair of distinct members of each of (G, k) groups."""
    first, second = np.triu_indices(groups.shape[1], 1)
    return np.stack([groups[:, first].ravel(), groups[:, second].ravel()])


class NormalEquations(BlockPattern):
    """H = Σ Jᵀ Ω J and g = Σ Jᵀ Ω r of a pose graph over its free nodes (held ones eliminated)."""

    def __init__(
        self,
        graph: PoseGraph,
        held: np.ndarray,
        backend: str = "auto",
        covariance_of: np.ndarray | None = None,
        previous: NormalEquations | None = None,
    ) -> None:
        """``covariance_of`` ((G, k) groups of node indices) and ``previous`` (the system of
        this graph before it grew): see ``BlockPattern``."""
        self.dof = graph.group.dof
        block_of = free_block_index(graph.num_nodes, held)
        super().__init__(
            block_of,
            graph.edges.i,
            graph.edges.j,
            graph.priors.i,
            self.dof,
            backend,
            covariance_of,
            previous,
        )

    def describes(self, graph: PoseGraph, held: np.ndarray) -> bool:
        """Whether these are the normal equations of ``graph``'s structure with ``held`` held."""
        block_of = free_block_index(graph.num_nodes, held)
        ends = [block_of[nodes] for nodes in (graph.edges.i, graph.edges.j, graph.priors.i)]
        return (
            block_of.size == self.block_of.size
            and all(new.size == old.size for new, old in zip(ends, self._ends, strict=True))
            and self._grows_into(block_of, *ends, graph.group.dof)
        )

    def for_covariance(self, backend: str) -> NormalEquations:
        """These normal equations (their pattern and positions shared) with a factoriser of
        their own, prepared for ``covariance_blocks`` of groups within the pattern."""
        other = copy.copy(self)
        other.cholesky = make_cholesky(
            self.indices, self.indptr, self.size, backend, True, self.cholesky
        )
        return other

    def normal_matrix(
        self,
        between: Linearization,
        between_information: np.ndarray,
        priors: Linearization,
        prior_information: np.ndarray,
    ) -> np.ndarray:
        """The CSC ``data`` of H = Σ Jᵀ Ω J from the Jacobians J of every edge (J = [Jᵢ Jⱼ] of a
        between edge), written straight into the stacked buffer that ``matrix_data`` sums."""
        cut = 4 * len(between.residuals) * self.dof**2
        blocks = np.empty(cut + len(priors.residuals) * self.dof**2)
        _products(between.jacobians, between_information, blocks[:cut])
        _products(priors.jacobians, prior_information, blocks[cut:])
        return self.matrix_data(blocks)

    def gradient(
        self,
        between: Linearization,
        between_information: np.ndarray,
        priors: Linearization,
        prior_information: np.ndarray,
    ) -> np.ndarray:
        """The gradient g = Σ Jᵀ Ω r, written straight into the stacked buffer that ``vector``
        sums."""
        cut = 2 * len(between.residuals) * self.dof
        pieces = np.empty(cut + len(priors.residuals) * self.dof)
        for part, linearization, information in (
            (pieces[:cut], between, between_information),
            (pieces[cut:], priors, prior_information),
        ):
            jacobians = linearization.jacobians
            weighted = np.einsum("mij,mj->mi", information, linearization.residuals)  # Ω r
            out = part.reshape(jacobians.shape[0], jacobians.shape[2])
            np.einsum("mij,mi->mj", jacobians, weighted, out=out)
        return self.vector(pieces)


def _products(jacobians: np.ndarray, information: np.ndarray, out: np.ndarray) -> None:
    """Write Jᵀ Ω J of every measurement into the flat buffer ``out`` (batched products: faster
    than ``einsum`` for these matrices, slower for the gradient's vectors)."""
    width = jacobians.shape[2]
    out = out.reshape(jacobians.shape[0], width, width)
    np.matmul(np.swapaxes(jacobians, 1, 2), information @ jacobians, out=out)
