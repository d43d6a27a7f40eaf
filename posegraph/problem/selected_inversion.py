"""Selected inversion: the entries of A⁻¹ that lie in the pattern of A's Cholesky factor L.

With A = L Lᵀ, cut L into supernodes: runs of consecutive columns C that share one pattern below
them, so that each holds a dense lower-triangular block L_CC and rows R under it. The trailing
part of Σ = A⁻¹ = L⁻ᵀ L⁻¹ from C on is the inverse of the trailing part of L Lᵀ, which gives

    U = L_RC L_CC⁻¹,   Σ_RC = −Σ_RR U,   Σ_CC = L_CC⁻ᵀ L_CC⁻¹ − Uᵀ Σ_RC

(Takahashi, Fagan & Chen 1973; in supernodal form, Lin, Yang, Meza, Lu, Ying & E 2011, "SelInv",
ACM TOMS 37(4)). Σ_RR lies in the pattern of the columns R, which are ancestors of C in the
elimination tree, so the supernodes are swept from the root down, and the entries in chosen
columns need only the supernodes on their paths to the root. The work is that of the numeric
factorisation; nothing of size n × n is formed. Supernodes at one depth of the tree do not
depend on each other: those of one depth and shape are computed together, as stacks.
"""

from __future__ import annotations

import numpy as np


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

    def positions(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Positions in an inverse's buffer of entries (rows ≥ columns); ``ValueError`` if one
        is outside L's pattern."""
        s = self.supernode_of[columns]
        keys = s * self.size + rows
        found = np.minimum(np.searchsorted(self._row_keys, keys), self._row_keys.size - 1)
        outside = self._row_keys[found] != keys
        if np.any(outside):
            k = int(np.flatnonzero(outside)[0])
            raise ValueError(f"entry ({rows[k]}, {columns[k]}) is outside the factor's pattern")
        row = found - self._row_offset[s]
        return self.offset[s] + row * self.width[s] + columns - self.first[s]


def _lower_blocks(factor: SupernodalFactor, supernodes: np.ndarray, height: int, width: int):
    """L's dense (g, height, width) blocks of supernodes of one shape (zero above the diagonal):
    column c of a supernode holds its rows from the c-th on, contiguous in L's data."""
    row, column = np.arange(height)[:, None], np.arange(width)[None, :]
    starts = factor._indptr[factor.first[supernodes][:, None] + np.arange(width)]  # (g, width)
    index = starts[:, None, :] + np.maximum(row - column, 0)
    return np.where(row >= column, factor._data[index], 0.0)


def _trailing_inverses(factor: SupernodalFactor, inverse: np.ndarray, rows: np.ndarray):
    """Σ_RR (g, k, k) for the rows R (g, k) below supernodes of one shape, gathered from the
    blocks of the ancestors that hold R's columns (already in ``inverse``). Entry (Rᵢ, Rⱼ),
    i ≥ j, lies in the block of the supernode t holding Rⱼ, in its row Rᵢ; where Rᵢ lies among
    t's rows is looked up once per run of R's columns that t holds."""
    count, k = rows.shape
    holder = factor.supernode_of[rows]  # (g, k), non-decreasing along k
    run_start = np.maximum.accumulate(
        np.where(np.diff(holder, axis=1, prepend=-1) != 0, np.arange(k), 0), axis=1
    )
    lower = np.tril(np.ones((k, k), dtype=bool))
    looked_up = lower & (run_start[:, None, :] == np.arange(k))  # (g, i, j): j starts a run
    g, i, j = np.nonzero(looked_up)
    keys = holder[g, j] * factor.size + rows[g, i]
    row_in_holder = np.zeros((count, k, k), dtype=np.int64)
    row_in_holder[g, i, j] = (
        np.searchsorted(factor._row_keys, keys) - factor._row_offset[holder[g, j]]
    )
    row_in_holder = np.take_along_axis(row_in_holder, run_start[:, None, :], axis=2)
    width = factor.width[holder][:, None, :]
    within = (rows - factor.first[holder])[:, None, :]
    positions = factor.offset[holder][:, None, :] + row_in_holder * width + within
    positions = np.where(lower, positions, np.swapaxes(positions, 1, 2))
    return inverse[positions]


def selected_inverse(factor: SupernodalFactor, columns: np.ndarray) -> np.ndarray:
    """Σ = (L Lᵀ)⁻¹ in L's pattern (a buffer laid out by ``factor.offset``), computed in the
    supernodes that hold ``columns`` and their ancestors; zero elsewhere."""
    inverse = np.zeros(factor.offset[-1])
    needed = factor.path_to_root(columns)
    shapes = np.stack([factor.depth[needed], factor.width[needed], factor.height[needed]])
    keys, group = np.unique(shapes, axis=1, return_inverse=True)
    for index, (_, width, height) in enumerate(keys.T):  # by depth, from the root down
        supernodes = needed[group.ravel() == index]
        lower = _lower_blocks(factor, supernodes, height, width)
        diagonal_inverse = np.linalg.inv(lower[:, :width])  # L_CC⁻¹
        sigma = np.zeros((supernodes.size, height, width))
        sigma[:, :width] = np.swapaxes(diagonal_inverse, 1, 2) @ diagonal_inverse
        if height > width:
            first_entries = factor._indptr[factor.first[supernodes]]
            rows = factor._indices[first_entries[:, None] + np.arange(width, height)]
            u = lower[:, width:] @ diagonal_inverse
            sigma[:, width:] = -_trailing_inverses(factor, inverse, rows) @ u
            sigma[:, :width] -= np.swapaxes(u, 1, 2) @ sigma[:, width:]
        places = factor.offset[supernodes][:, None] + np.arange(height * width)
        inverse[places] = sigma.reshape(supernodes.size, -1)
    return inverse


def inverse_blocks(factor: SupernodalFactor, groups: np.ndarray) -> np.ndarray:
    """The blocks (L Lᵀ)⁻¹[g, g], (G, c, c), for G groups g of c column indices (G, c), every
    pair of which must lie in L's pattern (``ValueError`` otherwise)."""
    inverse = selected_inverse(factor, groups.ravel())
    rows, columns = np.broadcast_arrays(groups[:, :, None], groups[:, None, :])
    lower, upper = np.maximum(rows, columns).ravel(), np.minimum(rows, columns).ravel()
    return inverse[factor.positions(lower, upper)].reshape(rows.shape)
