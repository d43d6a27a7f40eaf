"""Block-sparse symmetric systems on a sparsity pattern fixed once, and the normal equations
H δ = −g of a pose graph built on them.

``BlockPattern`` takes the graph's edges (and priors) over the free nodes and computes, once,
the CSC pattern of a matrix with one d × d block per free node and per pair of free nodes joined
by an edge (both triangles stored), where every edge block's d² entries land in the CSC ``data``
array, and the symbolic Cholesky factorisation. Assembling then takes a single ``np.bincount``
over stacked edge blocks; blocks that touch a held node go to a trash slot. No Python loop runs
over edges. A graph that grew by appended nodes, edges and priors gets its pattern by merging the
new blocks into the old pattern's sorted block list (a warm start), not by sorting them all again.

``NormalEquations`` uses it with d = dof for ``H = Σ Jᵀ Ω J`` and ``g = Σ Jᵀ Ω r``; the chordal
initialisation uses it with d = 2 or 3 for its linear systems.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from ..graph import PoseGraph
from .cholesky import NotPositiveDefinite, make_cholesky
from .factors import Linearization

if TYPE_CHECKING:
    import scipy.sparse

RIDGES = (1e-12, 1e-9, 1e-6)
"""Relative ridges ε (H + ε diag(H)) that ``factorize_regularized`` tries, smallest first."""


class BlockPattern:
    """The block pattern of Σₑ Jₑᵀ Wₑ Jₑ for edges i → j (and unary priors) over free nodes.

    ``block_of`` maps each node to its block index, or −1 for a held node. ``previous`` is a
    pattern built for the same edges and priors before more nodes, edges and priors were
    appended. If its nodes kept their blocks, it is grown instead of rebuilt (``self.grown``):
    only the appended edges' blocks are located and merged into its sorted block list.

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
        self.d = d
        self.block_of = block_of
        self.num_blocks = int(block_of.max(initial=-1)) + 1
        self.size = self.num_blocks * d
        a, b, p = block_of[edge_i], block_of[edge_j], block_of[prior_i]
        coupled = block_of[_pairs_within(covariance_of)]
        # Every edge contributes blocks (a, a), (b, b), (a, b), (b, a); every prior (p, p).
        self.grown = (
            previous is not None
            and coupled.size == 0
            and previous._grows_into(block_of, a, b, p, d)
        )
        self._ends = (a, b, p)
        if self.grown:
            block_keys, edge_blocks, prior_blocks = self._grow(previous, a, b, p)
        else:
            block_keys, edge_blocks, prior_blocks = self._locate(a, b, p, coupled)
        self._block_keys, self._edge_blocks = block_keys, edge_blocks
        self._prior_blocks = prior_blocks
        block_positions = self._layout(block_keys)

        # Stacked block order: every edge's 2d × 2d block [[H_ii, H_ij], [H_ji, H_jj]], then
        # every prior's d × d. Blocks touching a held node (index −1) select the last row: the
        # trash slot after ``data``. ``edge_blocks`` rows are (ii, jj, ij, ji).
        with_trash = np.concatenate([block_positions, np.full((1, d * d), self.nnz)])
        quadrants = with_trash[edge_blocks[[0, 2, 3, 1]]].reshape(2, 2, -1, d, d)
        self._block_positions = np.concatenate(
            [quadrants.transpose(2, 0, 3, 1, 4).ravel(), with_trash[prior_blocks].ravel()]
        )

        # Stacked vector order: every edge's i and j parts, then every prior's.
        ends = [self._vector_positions_of(a), self._vector_positions_of(b)]
        self._vector_positions = np.concatenate(
            [np.concatenate(ends, axis=1).ravel(), self._vector_positions_of(p).ravel()]
        )
        self.cholesky = make_cholesky(
            self.indices,
            self.indptr,
            self.size,
            backend,
            covariance_of is not None,
            previous.cholesky if self.grown else None,
        )

    def _vector_positions_of(self, blocks: np.ndarray) -> np.ndarray:
        """Each block's d positions in the stacked vector; past its end for a held node's."""
        within = np.arange(self.d)
        return np.where(blocks[:, None] >= 0, blocks[:, None] * self.d + within, self.size)

    def _keys(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Block keys col·nb + row (CSC order: by column, then row); −1 where a node is held."""
        return np.where((rows >= 0) & (cols >= 0), cols * max(self.num_blocks, 1) + rows, -1)

    def _edge_keys(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(4, m) keys of the blocks (a, a), (b, b), (a, b), (b, a) of edges a → b."""
        return np.stack([self._keys(a, a), self._keys(b, b), self._keys(a, b), self._keys(b, a)])

    def _locate(self, a, b, p, coupled: np.ndarray | None = None):
        """Sorted distinct block keys (every diagonal block, every edge and prior block, and
        both blocks of each ``coupled`` pair (2, k)) and the index among them of each edge block
        (4, m) and prior block (−1 where held)."""
        edge_keys, prior_keys = self._edge_keys(a, b), self._keys(p, p)
        diagonal = np.arange(self.num_blocks)
        keys = [self._keys(diagonal, diagonal), edge_keys[2:].ravel(), prior_keys]
        if coupled is not None:
            keys.append(self._edge_keys(*coupled)[2:].ravel())
        block_keys = np.unique(np.concatenate(keys))
        block_keys = block_keys[block_keys >= 0]

        def index(keys: np.ndarray) -> np.ndarray:
            return np.where(keys >= 0, np.searchsorted(block_keys, keys), -1)

        return block_keys, index(edge_keys), index(prior_keys)

    def _grows_into(self, block_of, a, b, p, d: int) -> bool:
        """Whether nodes' blocks ``block_of`` and edge (a → b) and prior (p) blocks extend this
        pattern's: its nodes, edges and priors come first, unchanged."""
        return (
            d == self.d
            and np.array_equal(block_of[: self.block_of.size], self.block_of)
            and all(
                np.array_equal(new[: old.size], old)
                for new, old in zip((a, b, p), self._ends, strict=True)
            )
        )

    def _grow(self, previous: BlockPattern, a, b, p):
        """``_locate`` for a graph that grew from ``previous``'s: its keys (re-encoded for the
        new block count) are kept, the appended edges' new keys are inserted in order, and old
        block indices shift by the number of keys inserted before them."""
        old_edges, old_priors = previous._edge_blocks.shape[1], previous._prior_blocks.size
        old_cols, old_rows = np.divmod(previous._block_keys, max(previous.num_blocks, 1))
        old_keys = self._keys(old_rows, old_cols)
        new_keys, new_edge_blocks, new_prior_blocks = self._locate(
            a[old_edges:], b[old_edges:], p[old_priors:]
        )
        found = np.minimum(np.searchsorted(old_keys, new_keys), max(old_keys.size - 1, 0))
        added = new_keys[old_keys[found] != new_keys] if old_keys.size else new_keys
        inserted_at = np.searchsorted(old_keys, added)
        block_keys = np.insert(old_keys, inserted_at, added)
        old_index = np.arange(old_keys.size)
        moved = old_index + np.searchsorted(inserted_at, old_index, side="right")
        located = np.searchsorted(block_keys, new_keys)
        edge_blocks = np.concatenate(
            [_mapped(previous._edge_blocks, moved), _mapped(new_edge_blocks, located)], axis=1
        )
        prior_blocks = np.concatenate(
            [_mapped(previous._prior_blocks, moved), _mapped(new_prior_blocks, located)]
        )
        return block_keys, edge_blocks, prior_blocks

    def _layout(self, block_keys: np.ndarray) -> np.ndarray:
        """Set the CSC ``indptr``, ``indices`` and diagonal positions for the sorted block keys;
        returns the positions in ``data`` of each block's d² entries (row-major)."""
        d, nb = self.d, max(self.num_blocks, 1)
        block_cols, block_rows = np.divmod(block_keys, nb)
        blocks_per_col = np.bincount(block_cols, minlength=self.num_blocks)
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
        self.indices[block_positions] = np.broadcast_to(
            (block_rows * d)[:, None, None] + within[None, :, None], (block_keys.size, d, d)
        ).reshape(-1, d * d)
        diagonal = np.arange(self.num_blocks)
        diagonal_blocks = block_positions[np.searchsorted(block_keys, diagonal * (nb + 1))]
        self.diagonal_positions = diagonal_blocks[:, within * d + within].ravel()
        return block_positions

    @property
    def nnz(self) -> int:
        return int(self.indptr[-1])

    def matrix_data(self, blocks: np.ndarray) -> np.ndarray:
        """CSC ``data`` summed from stacked blocks: every edge's 2d × 2d [[H_ii, H_ij],
        [H_ji, H_jj]], then every prior's d × d (any shape with these entries in this order)."""
        return np.bincount(self._block_positions, blocks.reshape(-1), self.nnz + 1)[:-1]

    def vector(self, pieces: np.ndarray) -> np.ndarray:
        """A length-``size`` vector summed from stacked pieces: every edge's 2d (its i part,
        then its j part), then every prior's d."""
        return np.bincount(self._vector_positions, pieces.reshape(-1), self.size + 1)[:-1]

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

    def diagonal(self, data: np.ndarray) -> np.ndarray:
        """diag(H) from its CSC data."""
        return data[self.diagonal_positions]

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation (an empty system's solution is empty)."""
        if self.size == 0:
            return np.zeros_like(rhs)
        return self.cholesky.solve(rhs)

    def scatter(self, solution: np.ndarray) -> np.ndarray:
        """A (size,) or (size, k) solution over the free blocks as (num_nodes, d) or
        (num_nodes, d, k), zero on held nodes."""
        columns = solution.shape[1:]
        full = np.zeros((self.block_of.size, self.d) + columns)
        free = self.block_of >= 0
        full[free] = solution.reshape((np.count_nonzero(free), self.d) + columns)
        return full

    def gather(self, per_node: np.ndarray) -> np.ndarray:
        """The (size,) vector of a (num_nodes, d) array's free blocks (``scatter``'s inverse)."""
        return per_node[self.block_of >= 0].reshape(-1)

    def matrix(self, data: np.ndarray) -> scipy.sparse.csc_matrix:
        """The matrix as scipy CSC (for inspection and tests)."""
        import scipy.sparse  # on use: a solve with CHOLMOD does without scipy

        return scipy.sparse.csc_matrix((data, self.indices, self.indptr), (self.size, self.size))


def _mapped(blocks: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``index[blocks]`` where a block is located, −1 where it is held (−1), even when
    ``index`` is empty (every node held)."""
    located = np.full_like(blocks, -1)
    kept = blocks >= 0
    located[kept] = index[blocks[kept]]
    return located


def _pairs_within(groups: np.ndarray | None) -> np.ndarray:
    """(2, m) node indices: every pair of distinct members of each of (G, k) groups."""
    if groups is None:
        return np.zeros((2, 0), dtype=np.int64)
    first, second = np.triu_indices(groups.shape[1], 1)
    return np.stack([groups[:, first].ravel(), groups[:, second].ravel()])


def free_block_index(num_nodes: int, held: np.ndarray) -> np.ndarray:
    """Block index of every node: consecutive over free nodes, −1 for held ones."""
    block_of = np.full(num_nodes, -1, dtype=np.int64)
    free = np.ones(num_nodes, dtype=bool)
    free[held] = False
    block_of[free] = np.arange(int(free.sum()))
    return block_of


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

    def assemble(
        self,
        between: Linearization,
        between_information: np.ndarray,
        priors: Linearization,
        prior_information: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The CSC ``data`` of H and the gradient g, from the Jacobians J of every edge (J =
        [Jᵢ Jⱼ] of a between edge): Jᵀ Ω J and Jᵀ Ω r, written straight into the stacked
        buffers that ``matrix_data`` and ``vector`` sum."""
        m, p, d = between.residuals.shape[0], priors.residuals.shape[0], self.dof
        edge_entries, edge_pieces = 4 * m * d * d, 2 * m * d
        blocks, pieces = np.empty(edge_entries + p * d * d), np.empty(edge_pieces + p * d)
        _normal_terms(between, between_information, blocks[:edge_entries], pieces[:edge_pieces])
        _normal_terms(priors, prior_information, blocks[edge_entries:], pieces[edge_pieces:])
        return self.matrix_data(blocks), self.vector(pieces)


def _normal_terms(
    linearization: Linearization, information: np.ndarray, blocks: np.ndarray, pieces: np.ndarray
) -> None:
    """Write Jᵀ Ω J and Jᵀ Ω r of every edge into the flat buffers ``blocks`` and ``pieces``."""
    jacobians = linearization.jacobians
    count, width = jacobians.shape[0], jacobians.shape[2]
    jt_omega = np.swapaxes(jacobians, 1, 2) @ information
    np.matmul(jt_omega, jacobians, out=blocks.reshape(count, width, width))
    np.matmul(jt_omega, linearization.residuals[:, :, None], out=pieces.reshape(count, width, 1))
