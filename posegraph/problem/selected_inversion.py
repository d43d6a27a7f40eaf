"""Selected inversion: the entries of A⁻¹ that lie in the pattern of A's Cholesky factor L.

With A = L Lᵀ, cut L into supernodes: runs of consecutive columns C that share one pattern below
them, so that each holds a dense lower-triangular block L_CC and rows R under it. The trailing
part of Σ = A⁻¹ = L⁻ᵀ L⁻¹ from C on is the inverse of the trailing part of L Lᵀ, which gives

    U = L_RC L_CC⁻¹,   Σ_RC = −Σ_RR U,   Σ_CC = L_CC⁻ᵀ L_CC⁻¹ − Uᵀ Σ_RC

(Takahashi, Fagan & Chen 1973; in supernodal form, Lin, Yang, Meza, Lu, Ying & E 2011, "SelInv",
ACM TOMS 37(4)). Σ_RR lies in the pattern of the columns R, which are ancestors of C in the
elimination tree, so the supernodes are swept from the root down, and the entries in chosen
columns need only the supernodes on their paths to the root. The work is that of the numeric
factorisation; nothing of size n × n is formed.
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

    def lower(self, s: int) -> np.ndarray:
        """L's dense (height, width) block of supernode s (zero above the diagonal)."""
        first, width, height = self.first[s], self.width[s], self.height[s]
        start, stop = self._indptr[first], self._indptr[first + width]
        column = np.repeat(np.arange(width), height - np.arange(width))
        row = np.arange(stop - start) - (self._indptr[first + column] - start) + column
        block = np.zeros((height, width))
        block[row, column] = self._data[start:stop]
        return block

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


def _trailing_inverse(
    factor: SupernodalFactor, inverse: np.ndarray, rows: np.ndarray
) -> np.ndarray:
    """Σ_RR (dense, symmetric) for the rows R below a supernode, gathered from the blocks of the
    ancestors that hold R's columns (already in ``inverse``)."""
    gathered = np.zeros((rows.size, rows.size))
    holder = factor.supernode_of[rows]
    starts = np.flatnonzero(np.concatenate([[True], holder[1:] != holder[:-1]]))
    for start, stop in zip(starts, np.append(starts[1:], rows.size), strict=True):
        t = holder[start]
        within = np.searchsorted(factor.rows(t), rows[start:])
        columns = rows[start:stop] - factor.first[t]
        gathered[start:, start:stop] = factor.block(inverse, t)[within][:, columns]
        gathered[start:stop, stop:] = gathered[stop:, start:stop].T
    return gathered


def selected_inverse(factor: SupernodalFactor, columns: np.ndarray) -> np.ndarray:
    """Σ = (L Lᵀ)⁻¹ in L's pattern (a buffer laid out by ``factor.offset``), computed in the
    supernodes that hold ``columns`` and their ancestors; zero elsewhere."""
    inverse = np.zeros(factor.offset[-1])
    for s in factor.path_to_root(columns)[::-1]:
        width = factor.width[s]
        lower = factor.lower(s)
        # numpy's LAPACK throughout: alternating with scipy's OpenBLAS (a second thread pool)
        # made each call's time vary up to fourfold on two cores.
        diagonal_inverse = np.linalg.inv(lower[:width])  # L_CC⁻¹
        sigma = factor.block(inverse, s)
        sigma[:width] = diagonal_inverse.T @ diagonal_inverse
        below = factor.rows(s)[width:]
        if below.size:
            u = lower[width:] @ diagonal_inverse
            sigma[width:] = -_trailing_inverse(factor, inverse, below) @ u
            sigma[:width] -= u.T @ sigma[width:]
    return inverse


def inverse_blocks(factor: SupernodalFactor, groups: np.ndarray) -> np.ndarray:
    """The blocks (L Lᵀ)⁻¹[g, g], (G, c, c), for G groups g of c column indices (G, c), every
    pair of which must lie in L's pattern (``ValueError`` otherwise)."""
    inverse = selected_inverse(factor, groups.ravel())
    rows, columns = np.broadcast_arrays(groups[:, :, None], groups[:, None, :])
    lower, upper = np.maximum(rows, columns).ravel(), np.minimum(rows, columns).ravel()
    return inverse[factor.positions(lower, upper)].reshape(rows.shape)
