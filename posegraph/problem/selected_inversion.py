"""Selected inversion: the entries of A⁻¹ that lie in the pattern of A's Cholesky factor L.

With A = L Lᵀ, cut L into supernodes: runs of consecutive columns C that share one pattern below
them, so that each holds a dense lower-triangular block L_CC and rows R under it. The trailing
part of Σ = A⁻¹ = L⁻ᵀ L⁻¹ from C on is the inverse of the trailing part of L Lᵀ, which gives

    U = L_RC L_CC⁻¹,   Σ_RC = −Σ_RR U,   Σ_CC = L_CC⁻ᵀ L_CC⁻¹ − Uᵀ Σ_RC

(Takahashi, Fagan & Chen 1973; in supernodal form, Lin, Yang, Meza, Lu, Ying & E 2011, "SelInv",
ACM TOMS 37(4)). R lies among the rows of C's parent supernode in the elimination tree (Liu
1990, "The role of elimination trees in sparse factorization", SIAM J. Matrix Anal. Appl.
11(1)), so Σ_RR is part of the parent's front Σ[rows, rows], kept, depth by depth, until its
children have read it: each of R's rows is looked up once, not each entry. The supernodes are
swept from the root down, and the entries in chosen columns need only the supernodes on their
paths to the root. The work is that of the numeric factorisation; nothing of size n × n is
formed. Supernodes at one depth of the tree do not depend on each other: those of one depth and
shape are computed together, as stacks.
"""

from __future__ import annotations

import numpy as np

TRIANGULAR_LEAF = 64
"""Lower-triangular blocks up to this width are inverted by numpy's LU ``inv``; wider ones by
halves (``_triangular_inverse``)."""
SCATTERED = 8
"""Groups of more supernodes than this are written into a buffer by one scatter; fewer, block
by block (``_write``)."""


class SupernodalFactor:
    """A lower-triangular factor L, given in CSC with sorted row indices, cut into supernodes.
    Its pattern must be a Cholesky factor's: if rows a > b both lie below the diagonal of one
    column, (a, b) lies in the pattern too."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> None:
        n = self.size = indptr.size - 1
        counts = np.diff(indptr)
        below_diagonal = indices[np.minimum(indptr[:-1] + 1, indices.size - 1)]
        # Column j + 1 continues j's supernode if pattern(j) = {j} ∪ pattern(j + 1).
        continues = (counts[:-1] == counts[1:] + 1) & (below_diagonal[:-1] == np.arange(1, n))
        self.first = np.flatnonzero(np.concatenate([[True], ~continues]))
        self.width = np.diff(np.append(self.first, n))
        self.height = counts[self.first]
        self.supernode_of = np.repeat(np.arange(self.first.size), self.width)
        self._indptr, self._indices, self._data = indptr, indices, data
        self.parent = np.full(self.first.size, -1)
        has_rows = self.height > self.width
        first_row_below = indices[indptr[self.first[has_rows]] + self.width[has_rows]]
        self.parent[has_rows] = self.supernode_of[first_row_below]
        self.depth = np.zeros(self.first.size, dtype=np.int64)
        ancestor = self.parent.copy()
        while np.any(ancestor >= 0):
            self.depth += ancestor >= 0
            ancestor = np.where(ancestor >= 0, self.parent[ancestor], -1)
        # An inverse is kept as one flat buffer: supernode s's (height, width) row-major block
        # at offset[s]. Row keys s·n + row of every supernode, sorted, locate entries in it.
        self.offset = np.concatenate([[0], np.cumsum(self.height * self.width)])
        self._row_offset = np.concatenate([[0], np.cumsum(self.height)])
        supernode = np.repeat(np.arange(self.first.size), self.height)
        within = np.arange(self._row_offset[-1]) - self._row_offset[supernode]
        self._row_keys = supernode * n + indices[indptr[self.first][supernode] + within]

    def rows(self, s: int) -> np.ndarray:
        """Row indices of supernode s: its own columns, then the rows R below them."""
        start = self._indptr[self.first[s]]
        return self._indices[start : start + self.height[s]]

    def block(self, buffer: np.ndarray, s: int) -> np.ndarray:
        """Supernode s's (height, width) view into an inverse's ``buffer``."""
        return buffer[self.offset[s] : self.offset[s + 1]].reshape(self.height[s], self.width[s])

    def path_to_root(self, columns: np.ndarray) -> np.ndarray:
        """The supernodes holding ``columns`` and all their ancestors, in increasing order."""
        needed = np.zeros(self.first.size, dtype=bool)
        for s in np.unique(self.supernode_of[columns]):
            while s >= 0 and not needed[s]:
                needed[s] = True
                s = self.parent[s]
        return np.flatnonzero(needed)

    def rows_within(self, supernodes: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Where each of ``rows`` lies among the rows of its supernode in ``supernodes``
        (broadcast together), −1 where it is not one of them."""
        keys = supernodes * self.size + rows
        found = np.minimum(np.searchsorted(self._row_keys, keys), self._row_keys.size - 1)
        return np.where(self._row_keys[found] == keys, found - self._row_offset[supernodes], -1)

    def positions(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Positions in an inverse's buffer of entries (rows ≥ columns); ``ValueError`` if one
        is outside L's pattern."""
        s = self.supernode_of[columns]
        row = self.rows_within(s, rows)
        if np.any(row < 0):
            k = int(np.flatnonzero(row < 0)[0])
            raise ValueError(f"entry ({rows[k]}, {columns[k]}) is outside the factor's pattern")
        return self.offset[s] + row * self.width[s] + columns - self.first[s]


def _lower_blocks(factor: SupernodalFactor, supernodes: np.ndarray, height: int, width: int):
    """L's dense (g, height, width) blocks of supernodes of one shape (zero above the diagonal):
    column c of a supernode holds its rows from the c-th on, contiguous in L's data."""
    row, column = np.arange(height)[:, None], np.arange(width)[None, :]
    starts = factor._indptr[factor.first[supernodes][:, None] + np.arange(width)]  # (g, width)
    index = starts[:, None, :] + np.maximum(row - column, 0)
    return np.where(row >= column, factor._data[index], 0.0)


def _triangular_inverse(lower: np.ndarray) -> np.ndarray:
    """The inverses of stacked (g, w, w) lower-triangular matrices, by halves:
    [[A, 0], [B, C]]⁻¹ = [[A⁻¹, 0], [−C⁻¹ B A⁻¹, C⁻¹]] (a recursive TRTRI: about w³/3
    multiplications, in matrix products, where an LU inverse takes 2w³)."""
    width = lower.shape[-1]
    if width <= TRIANGULAR_LEAF:
        return np.linalg.inv(lower)
    half = width // 2
    inverse = np.zeros_like(lower)
    top = inverse[:, :half, :half] = _triangular_inverse(lower[:, :half, :half])
    bottom = inverse[:, half:, half:] = _triangular_inverse(lower[:, half:, half:])
    inverse[:, half:, :half] = -(bottom @ lower[:, half:, :half]) @ top
    return inverse


def _write(buffer: np.ndarray, starts: np.ndarray, blocks: np.ndarray) -> None:
    """Each of the stacked ``blocks`` (g, ...), flattened, into ``buffer`` from its start: as
    slices where there are few (a large block's scatter would index every entry), else by one
    scatter."""
    flat = blocks.reshape(blocks.shape[0], -1)
    if flat.shape[0] > SCATTERED:
        buffer[starts[:, None] + np.arange(flat.shape[1])] = flat
        return
    for start, block in zip(starts.tolist(), flat, strict=True):
        buffer[start : start + block.size] = block


def _fronts(factor: SupernodalFactor, needed: np.ndarray) -> tuple[np.ndarray, dict]:
    """Where each parent among the ``needed`` supernodes keeps its front Σ[rows(s), rows(s)],
    (height, height) row-major, in the flat buffer of its depth: the offsets (−1 for
    supernodes that are no parent) and one empty buffer per depth."""
    parent = factor.parent[needed]
    parents = np.unique(parent[parent >= 0])
    offsets = np.full(factor.first.size, -1)
    buffers = {}
    for depth in np.unique(factor.depth[parents]).tolist():
        at = parents[factor.depth[parents] == depth]
        sizes = factor.height[at] ** 2
        offsets[at] = np.cumsum(sizes) - sizes
        buffers[depth] = np.empty(int(sizes.sum()))
    return offsets, buffers


def selected_inverse(factor: SupernodalFactor, columns: np.ndarray) -> np.ndarray:
    """Σ = (L Lᵀ)⁻¹ in L's pattern (a buffer laid out by ``factor.offset``), computed in the
    supernodes that hold ``columns`` and their ancestors; zero elsewhere."""
    inverse = np.zeros(factor.offset[-1])
    needed = factor.path_to_root(columns)
    front_offsets, fronts = _fronts(factor, needed)
    shapes = np.stack([factor.depth[needed], factor.width[needed], factor.height[needed]])
    keys, group = np.unique(shapes, axis=1, return_inverse=True)
    for index, (depth, width, height) in enumerate(keys.T):  # by depth, from the root down
        supernodes = needed[group.ravel() == index]
        lower = _lower_blocks(factor, supernodes, height, width)
        diagonal_inverse = _triangular_inverse(lower[:, :width])  # L_CC⁻¹
        front = np.empty((supernodes.size, height, height))
        front[:, :width, :width] = np.swapaxes(diagonal_inverse, 1, 2) @ diagonal_inverse
        if height > width:
            parent = factor.parent[supernodes]
            first_entries = factor._indptr[factor.first[supernodes]]
            rows = factor._indices[first_entries[:, None] + np.arange(width, height)]
            within = factor.rows_within(parent[:, None], rows)  # R among the parent's rows
            places = (
                front_offsets[parent][:, None, None]
                + within[:, :, None] * factor.height[parent][:, None, None]
                + within[:, None, :]
            )
            front[:, width:, width:] = fronts[depth - 1][places]  # Σ_RR
            u = lower[:, width:] @ diagonal_inverse
            front[:, width:, :width] = -front[:, width:, width:] @ u  # Σ_RC
            front[:, :width, :width] -= np.swapaxes(u, 1, 2) @ front[:, width:, :width]
            front[:, :width, width:] = np.swapaxes(front[:, width:, :width], 1, 2)
        _write(inverse, factor.offset[supernodes], front[:, :, :width])
        kept = front_offsets[supernodes] >= 0
        if kept.any():
            _write(fronts[depth], front_offsets[supernodes[kept]], front[kept])
        fronts.pop(depth - 2, None)  # the grandparents' fronts have served their last children
    return inverse


def inverse_blocks(factor: SupernodalFactor, groups: np.ndarray) -> np.ndarray:
    """The blocks (L Lᵀ)⁻¹[g, g], (G, c, c), for G groups g of c column indices (G, c), every
    pair of which must lie in L's pattern (``ValueError`` otherwise)."""
    inverse = selected_inverse(factor, groups.ravel())
    count, size = groups.shape
    a, b = np.tril_indices(size)  # a block is symmetric: its lower triangle is looked up
    rows, columns = groups[:, a].ravel(), groups[:, b].ravel()
    lower = inverse[factor.positions(np.maximum(rows, columns), np.minimum(rows, columns))]
    blocks = np.empty((count, size, size))
    blocks[:, a, b] = blocks[:, b, a] = lower.reshape(count, a.size)
    return blocks
