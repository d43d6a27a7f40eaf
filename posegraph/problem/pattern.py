"""The CSC layout of a block-sparse symmetric matrix: one d × d block per free node and per pair
of free nodes joined by an edge (both triangles stored), and where every edge's and prior's
block entries land in the CSC ``data`` array, so that assembling takes a single
``np.bincount`` over stacked blocks; blocks that touch a held node go to a trash slot. No
Python loop runs over edges. A graph that grew by appended nodes, edges and priors gets its
layout by merging the new blocks into the old sorted block list, and where they all touch an
appended node (a streamed pose), by moving the old entries by their column's shift, not by
laying out every block again.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .cholesky import Appended

if TYPE_CHECKING:
    import scipy.sparse

KEY_SHIFT = 32
"""A block's key is its column shifted left by this many bits, plus its row."""
KEY_ROW = (1 << KEY_SHIFT) - 1


class BlockLayout:
    """The block layout of Σₑ Jₑᵀ Wₑ Jₑ for edges i → j (and unary priors) over free nodes.

    ``block_of`` maps each node to its block index, or −1 for a held node. ``coupled``: (2, k)
    pairs of nodes whose blocks join the pattern though no edge joins them. ``previous`` is a
    layout built for the same edges and priors before more nodes, edges and priors were
    appended. If its nodes kept their blocks, it is grown instead of rebuilt (``self.grown``):
    only the appended edges' blocks are located and merged into its sorted block list.
    """

    def __init__(
        self,
        block_of: np.ndarray,
        edge_i: np.ndarray,
        edge_j: np.ndarray,
        prior_i: np.ndarray,
        d: int,
        coupled: np.ndarray | None = None,
        previous: BlockLayout | None = None,
    ) -> None:
        self.d = d
        self.block_of = block_of
        self.num_blocks = int(block_of.max(initial=-1)) + 1
        self.size = self.num_blocks * d
        a, b, p = block_of[edge_i], block_of[edge_j], block_of[prior_i]
        coupled = np.zeros((2, 0), dtype=np.int64) if coupled is None else block_of[coupled]
        # Every edge contributes blocks (a, a), (b, b), (a, b), (b, a); every prior (p, p).
        self.grown = (
            previous is not None
            and coupled.size == 0
            and previous._grows_into(block_of, a, b, p, d)
        )
        self._ends = (a, b, p)
        self.appended: Appended | None = None
        """How the CSC pattern extends ``previous``'s, where it was grown and that is known."""
        if not self.grown:
            edge_blocks, prior_blocks = self._locate(a, b, p, coupled)
            self._set_indptr()
            self._layout(edge_blocks, prior_blocks)
            return
        self._block_keys, appended = self._grow(previous)
        self._set_indptr()
        if appended is None:  # a block between old nodes was inserted: laid out anew
            self._layout(self._index(self._edge_keys(a, b)), self._index(self._keys(p, p)))
        else:
            self.appended = self._extend_layout(previous, appended)

    def _keys(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Block keys col·2³² + row (CSC order: by column, then row); −1 where a node is held.
        The keys of a block do not change as the pattern grows."""
        return np.where((rows >= 0) & (cols >= 0), (cols << KEY_SHIFT) + rows, -1)

    def _edge_keys(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(4, m) keys of the blocks (a, a), (b, b), (a, b), (b, a) of edges a → b."""
        return np.stack([self._keys(a, a), self._keys(b, b), self._keys(a, b), self._keys(b, a)])

    def _locate(self, a, b, p, coupled: np.ndarray):
        """Set the sorted distinct block keys (every diagonal block, every edge and prior block,
        and both blocks of each ``coupled`` pair (2, k)); returns the index among them of each
        edge block (4, m) and prior block (−1 where held)."""
        edge_keys, prior_keys = self._edge_keys(a, b), self._keys(p, p)
        diagonal = np.arange(self.num_blocks)
        coupled_keys = self._edge_keys(*coupled)[2:]
        self._block_keys = _distinct(
            self._keys(diagonal, diagonal), edge_keys[2:], prior_keys, coupled_keys
        )
        return self._index(edge_keys), self._index(prior_keys)

    def _index(self, keys: np.ndarray) -> np.ndarray:
        """The index of each block key among the sorted keys; −1 for a held node's (−1)."""
        return _located(keys, self._block_keys)

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

    def _grow(self, previous: BlockLayout) -> tuple[np.ndarray, np.ndarray | None]:
        """The sorted keys of a graph that grew from ``previous``'s: its keys, with the new
        keys of the appended edges and priors inserted in order. Also returns the inserted
        keys' indices if each inserted block touches an appended node (it then ends its column:
        ``_extend_layout``), else None."""
        a, b, p = self._ends
        old_edges, old_priors = previous._ends[0].size, previous._ends[2].size
        old_keys = previous._block_keys
        diagonal = np.arange(previous.num_blocks, self.num_blocks)
        new_keys = _distinct(
            self._keys(diagonal, diagonal),
            self._edge_keys(a[old_edges:], b[old_edges:])[2:],
            self._keys(p[old_priors:], p[old_priors:]),
        )
        found = np.minimum(np.searchsorted(old_keys, new_keys), max(old_keys.size - 1, 0))
        added = new_keys[old_keys[found] != new_keys] if old_keys.size else new_keys
        inserted_at = np.searchsorted(old_keys, added)
        block_keys = np.insert(old_keys, inserted_at, added)
        old_blocks = previous.num_blocks
        if np.all(((added >> KEY_SHIFT) >= old_blocks) | ((added & KEY_ROW) >= old_blocks)):
            return block_keys, inserted_at + np.arange(added.size)
        return block_keys, None

    def _set_indptr(self) -> None:
        """The CSC ``indptr`` of the sorted block keys, and each block column's first key."""
        d = self.d
        block_cols = self._block_keys >> KEY_SHIFT
        blocks_per_col = np.bincount(block_cols, minlength=self.num_blocks)
        self._first_block_of_col = np.concatenate([[0], np.cumsum(blocks_per_col)[:-1]])
        self.indptr = np.concatenate([[0], np.cumsum(np.repeat(blocks_per_col * d, d))])

    def _positions(self, blocks: np.ndarray) -> np.ndarray:
        """(k, d²): where in ``data`` the entries of these blocks (indices among the keys) sit,
        row-major. Entry (p, q) of a block in block column c, ranked r there, is in scalar column
        c·d + q, after r·d entries."""
        d, within = self.d, np.arange(self.d)
        cols = self._block_keys[blocks] >> KEY_SHIFT
        rank = blocks - self._first_block_of_col[cols]
        positions = (
            self.indptr[(cols * d)[:, None, None] + within[None, None, :]]
            + (rank * d)[:, None, None]
            + within[None, :, None]
        )
        return positions.reshape(-1, d * d)

    def _rows(self, blocks: np.ndarray) -> np.ndarray:
        """(k, d²): the row of each entry of these blocks, in ``_positions``' order."""
        d, within = self.d, np.arange(self.d)
        rows = self._block_keys[blocks] & KEY_ROW
        entries = (rows * d)[:, None, None] + within[None, :, None]
        return np.broadcast_to(entries, (blocks.size, d, d)).reshape(-1, d * d)

    def diagonal_blocks(self, nodes: np.ndarray | None = None) -> np.ndarray:
        """(k, d, d): where in ``data`` the entries of these nodes' diagonal blocks sit (by
        default every free node's), row-major."""
        nodes = np.arange(self.num_blocks) if nodes is None else nodes
        blocks = np.searchsorted(self._block_keys, self._keys(nodes, nodes))
        return self._positions(blocks).reshape(-1, self.d, self.d)

    def _diagonal_positions(self, nodes: np.ndarray) -> np.ndarray:
        """The positions in ``data`` of the diagonals of these blocks' diagonal blocks."""
        within = np.arange(self.d)
        return self.diagonal_blocks(nodes)[:, within, within].ravel()

    def _layout(self, edge_blocks: np.ndarray, prior_blocks: np.ndarray) -> None:
        """Set the CSC ``indices``, the diagonal's positions, and where each stacked block and
        vector piece of the edges and priors is summed (``matrix_data``, ``vector``)."""
        blocks = np.arange(self._block_keys.size)
        block_positions = self._positions(blocks)
        self.indices = np.empty(self.nnz, dtype=np.int64)
        self.indices[block_positions] = self._rows(blocks)
        self.diagonal_positions = self._diagonal_positions(np.arange(self.num_blocks))
        self._block_positions = np.concatenate(
            self._stacked_blocks(edge_blocks, prior_blocks, block_positions)
        )
        self._vector_positions = np.concatenate(self._stacked_vector(*self._ends))

    def _extend_layout(self, previous: BlockLayout, appended: np.ndarray) -> Appended:
        """``_layout`` for a pattern grown from ``previous``'s where every inserted block
        (``appended``, indices among the keys) touches an appended node. In an old column those
        come after every old entry, so each old entry moves by its column's shift, and only the
        inserted blocks and the appended edges and priors are located. Returns how the CSC
        pattern extends ``previous``'s, for the factoriser's set-up."""
        d, (a, b, p) = self.d, self._ends
        old_edges, old_priors = previous._ends[0].size, previous._ends[2].size
        shift = self.indptr[: previous.size] - previous.indptr[: previous.size]
        relocated = np.arange(previous.nnz + 1)
        relocated[:-1] += np.repeat(shift, np.diff(previous.indptr))
        relocated[-1] = self.nnz  # the trash slot
        self.indices = np.empty(self.nnz, dtype=np.int64)
        self.indices[relocated[:-1]] = previous.indices
        inserted = self._positions(appended)
        self.indices[inserted] = self._rows(appended)
        new_nodes = np.arange(previous.num_blocks, self.num_blocks)
        self.diagonal_positions = np.concatenate(
            [relocated[previous.diagonal_positions], self._diagonal_positions(new_nodes)]
        )

        new_edges = self._edge_keys(a[old_edges:], b[old_edges:])
        new_priors = self._keys(p[old_priors:], p[old_priors:])
        touched = _distinct(new_edges, new_priors)
        positions = self._positions(self._index(touched))
        local = (_located(new_edges, touched), _located(new_priors, touched))
        blocks = self._stacked_blocks(*local, positions)
        self._block_positions = _spliced(
            previous._block_positions, 4 * old_edges * d * d, relocated, *blocks
        )
        moved = np.arange(previous.size + 1)
        moved[-1] = self.size  # a held node's piece: past the end
        pieces = self._stacked_vector(a[old_edges:], b[old_edges:], p[old_priors:])
        self._vector_positions = _spliced(
            previous._vector_positions, 2 * old_edges * d, moved, *pieces
        )
        return Appended(relocated, np.sort(inserted, axis=None))

    def _stacked_blocks(
        self, edge_blocks: np.ndarray, prior_blocks: np.ndarray, positions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where in ``data`` each entry of the stacked blocks goes: every edge's 2d × 2d block
        [[H_ii, H_ij], [H_ji, H_jj]] (``edge_blocks`` rows are ii, jj, ij, ji), then every
        prior's d × d, given each block's ``positions`` (rows indexed by the blocks). A block
        touching a held node (−1) selects the last row: the trash slot after ``data``."""
        d = self.d
        with_trash = np.concatenate([positions, np.full((1, d * d), self.nnz)])
        quadrants = with_trash[edge_blocks[[0, 2, 3, 1]]].reshape(2, 2, -1, d, d)
        return quadrants.transpose(2, 0, 3, 1, 4).ravel(), with_trash[prior_blocks].ravel()

    def _stacked_vector(
        self, a: np.ndarray, b: np.ndarray, p: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where each stacked vector piece goes: every edge's i part then j part (edges
        between blocks ``a`` and ``b``), then every prior's (on blocks ``p``); past the end
        for a held node's."""
        within = np.arange(self.d)

        def of(blocks: np.ndarray) -> np.ndarray:
            return np.where(blocks[:, None] >= 0, blocks[:, None] * self.d + within, self.size)

        return np.concatenate([of(a), of(b)], axis=1).ravel(), of(p).ravel()

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

    def diagonal(self, data: np.ndarray) -> np.ndarray:
        """diag(H) from its CSC data."""
        return data[self.diagonal_positions]

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


def _distinct(*keys: np.ndarray) -> np.ndarray:
    """The sorted distinct block keys in these arrays, a held node's (−1) left out."""
    distinct = np.unique(np.concatenate([array.ravel() for array in keys]))
    return distinct[distinct >= 0]


def _located(keys: np.ndarray, among: np.ndarray) -> np.ndarray:
    """The index of each block key among the sorted keys ``among``; −1 for a held node's."""
    return np.where(keys >= 0, np.searchsorted(among, keys), -1)


def _spliced(
    old: np.ndarray, cut: int, moved: np.ndarray, edges: np.ndarray, priors: np.ndarray
) -> np.ndarray:
    """Stacked positions of a grown pattern: ``old``'s first ``cut`` (its edges'), the appended
    ``edges``', the rest of ``old`` (its priors'), the appended ``priors``'; each of ``old``'s
    positions p taken to ``moved[p]``. Written into one array, as these are a pattern's largest
    arrays; ``take`` in "clip" mode, as numpy buffers ``out`` in its default mode (every
    position here is in range)."""
    spliced = np.empty(old.size + edges.size + priors.size, dtype=old.dtype)
    middle = cut + edges.size
    np.take(moved, old[:cut], out=spliced[:cut], mode="clip")
    spliced[cut:middle] = edges
    np.take(moved, old[cut:], out=spliced[middle : middle + old.size - cut], mode="clip")
    spliced[middle + old.size - cut :] = priors
    return spliced


def free_block_index(num_nodes: int, held: np.ndarray) -> np.ndarray:
    """Block index of every node: consecutive over free nodes, −1 for held ones."""
    block_of = np.full(num_nodes, -1, dtype=np.int64)
    free = np.ones(num_nodes, dtype=bool)
    free[held] = False
    block_of[free] = np.arange(int(free.sum()))
    return block_of
