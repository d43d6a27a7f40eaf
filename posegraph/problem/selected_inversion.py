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
import threadpoolctl

TRIANGULAR_LEAF = 64
"""Lower-triangular blocks up to this width are inverted by numpy's LU ``inv``; wider ones by
halves (``_triangular_inverse``)."""


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
        # Row keys s·n + row of every supernode, sorted, locate a row among its rows.
        self._row_offset = np.concatenate([[0], np.cumsum(self.height)])
        supernode = np.repeat(np.arange(self.first.size), self.height)
        within = np.arange(self._row_offset[-1]) - self._row_offset[supernode]
        self._row_keys = supernode * n + indices[indptr[self.first][supernode] + within]

    def rows(self, s: int) -> np.ndarray:
        """Row indices of supernode s: its own columns, then the rows R below them."""
        start = self._indptr[self.first[s]]
        return self._indices[start : start + self.height[s]]

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

    def locate(self, rows: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, ...]:
        """The supernode of each entry (rows ≥ columns), its row among the supernode's rows and
        its column among its columns; ``ValueError`` if one is outside L's pattern."""
        s = self.supernode_of[columns]
        row = rows - self.first[s]  # right for rows among the supernode's own columns
        below = row >= self.width[s]
        row[below] = self.rows_within(s[below], rows[below])
        if np.any(row < 0):
            k = int(np.flatnonzero(row < 0)[0])
            raise ValueError(f"entry ({rows[k]}, {columns[k]}) is outside the factor's pattern")
        return s, row, columns - self.first[s]


def _lower_blocks(factor: SupernodalFactor, supernodes: np.ndarray, height: int, width: int):
    """L's dense (g, height, width) blocks of supernodes of one shape (zero above the diagonal):
    column c of a supernode holds its rows from the c-th on, height − c entries that follow
    column c − 1's in L's data. A lone supernode's columns are copied as slices."""
    starts = factor._indptr[factor.first[supernodes]]
    if supernodes.size == 1 and width > TRIANGULAR_LEAF:
        columns = np.zeros((1, width, height))  # Lᵀ, row by row
        offset = int(starts[0])
        for column in range(width):
            columns[0, column, column:] = factor._data[offset : offset + height - column]
            offset += height - column
        return np.swapaxes(columns, 1, 2)
    row, column = np.arange(height)[:, None], np.arange(width)[None, :]
    within = column * height - column * (column - 1) // 2 + np.maximum(row - column, 0)
    lower = factor._data.take(starts[:, None, None] + within)
    lower[:, :width] *= row[:width] >= column
    return lower


def _triangular_inverse(lower: np.ndarray) -> np.ndarray:
    """The inverses of stacked (g, w, w) lower-triangular matrices, by halves:
    [[A, 0], [B, C]]⁻¹ = [[A⁻¹, 0], [−C⁻¹ B A⁻¹, C⁻¹]] (a recursive TRTRI: about w³/3
    multiplications, where an LU inverse takes 2w³)."""
    width = lower.shape[-1]
    if width <= TRIANGULAR_LEAF:
        return np.linalg.inv(lower)
    half = width // 2
    inverse = np.zeros_like(lower)
    top = inverse[:, :half, :half] = _triangular_inverse(lower[:, :half, :half])
    bottom = inverse[:, half:, half:] = _triangular_inverse(lower[:, half:, half:])
    inverse[:, half:, :half] = -_times_lower(_lower_times(bottom, lower[:, half:, :half]), top)
    return inverse


def _lower_times(lower: np.ndarray, dense: np.ndarray) -> np.ndarray:
    """L X for stacked lower-triangular L (g, n, n) and X (g, n, k), by halves, so that L's
    zero upper right is not multiplied: about n²k multiplications, where a product of the full
    matrices takes 2n²k (a recursive TRMM)."""
    width = lower.shape[-1]
    if width <= TRIANGULAR_LEAF:
        return lower @ dense
    half = width // 2
    product = np.empty_like(dense)
    product[:, :half] = _lower_times(lower[:, :half, :half], dense[:, :half])
    product[:, half:] = lower[:, half:, :half] @ dense[:, :half]
    product[:, half:] += _lower_times(lower[:, half:, half:], dense[:, half:])
    return product


def _times_lower(dense: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """X L for X (g, k, n) and stacked lower-triangular L (g, n, n), by halves, as
    ``_lower_times``: [X₁ X₂] [[A, 0], [B, C]] = [X₁ A + X₂ B, X₂ C]."""
    width = lower.shape[-1]
    if width <= TRIANGULAR_LEAF:
        return dense @ lower
    half = width // 2
    product = np.empty_like(dense)
    product[..., :half] = _times_lower(dense[..., :half], lower[:, :half, :half])
    product[..., :half] += dense[..., half:] @ lower[:, half:, :half]
    product[..., half:] = _times_lower(dense[..., half:], lower[:, half:, half:])
    return product


def _gram_of_lower(lower: np.ndarray) -> np.ndarray:
    """Lᵀ L of stacked lower-triangular (g, w, w) matrices, by halves: with L = [[A, 0], [B, C]],
    Lᵀ L = [[AᵀA + BᵀB, BᵀC], [CᵀB, CᵀC]] (a recursive LAUUM: about 2w³/3 multiplications,
    where a product of the full matrices takes 2w³)."""
    width = lower.shape[-1]
    if width <= TRIANGULAR_LEAF:
        return np.swapaxes(lower, 1, 2) @ lower
    half = width // 2
    below, right = lower[:, half:, :half], lower[:, half:, half:]
    gram = np.empty_like(lower)
    gram[:, :half, :half] = _gram_of_lower(lower[:, :half, :half])
    gram[:, :half, :half] += np.swapaxes(below, 1, 2) @ below
    gram[:, :half, half:] = _times_lower(np.swapaxes(below, 1, 2), right)
    gram[:, half:, :half] = np.swapaxes(gram[:, :half, half:], 1, 2)
    gram[:, half:, half:] = _gram_of_lower(right)
    return gram


class SelectedInverse:
    """Σ = (L Lᵀ)⁻¹ in L's pattern, in the supernodes that ``selected_inverse`` computed: the
    (height, width) block of each, row-major, from ``offset[s]`` in one buffer (−1 for those
    not computed)."""

    def __init__(self, factor: SupernodalFactor, buffer: np.ndarray, offset: np.ndarray) -> None:
        self.factor, self.buffer, self.offset = factor, buffer, offset

    def block(self, s: int) -> np.ndarray:
        """Supernode s's (height, width) block, a view."""
        size = self.factor.height[s] * self.factor.width[s]
        return self.buffer[self.offset[s] : self.offset[s] + size].reshape(
            self.factor.height[s], self.factor.width[s]
        )

    def entries(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Σ's entries (rows ≥ columns); ``ValueError`` if one is outside L's pattern or in a
        supernode not computed."""
        s, row, column = self.factor.locate(rows, columns)
        if np.any(self.offset[s] < 0):
            raise ValueError("an entry lies in a supernode whose inverse was not computed")
        return self.buffer[self.offset[s] + row * self.factor.width[s] + column]


class _Fronts:
    """The fronts Σ[rows(s), rows(s)] of computed parents, (g, height, height) per group of
    supernodes computed together, kept until the children below them have read their Σ_RR."""

    def __init__(self, factor: SupernodalFactor, needed: np.ndarray) -> None:
        self.factor = factor
        self.is_parent = np.zeros(factor.first.size, dtype=bool)
        self.is_parent[factor.parent[needed][factor.parent[needed] >= 0]] = True
        self.group = np.full(factor.first.size, -1)
        self.slot = np.full(factor.first.size, -1)
        self.kept: dict[int, tuple[int, np.ndarray]] = {}

    def keep(self, index: int, depth: int, supernodes: np.ndarray, front: np.ndarray) -> None:
        """Keep group ``index``'s fronts if a supernode of it is a parent, and drop those two
        levels up, whose children have all been computed."""
        for old in [k for k, (at, _) in self.kept.items() if at < depth - 1]:
            del self.kept[old]
        if self.is_parent[supernodes].any():
            self.group[supernodes], self.slot[supernodes] = index, np.arange(supernodes.size)
            self.kept[index] = (depth, front)

    def lower_right(self, supernodes: np.ndarray, rows: np.ndarray, out: np.ndarray) -> None:
        """Σ_RR of ``supernodes`` (rows R below each, (g, r)) into ``out`` (g, r, r), read from
        their parents' fronts: each of R's rows looked up once among the parent's rows."""
        parent = self.factor.parent[supernodes]
        within = self.factor.rows_within(parent[:, None], rows)
        groups = self.group[parent]
        first, last = int(groups.min()), int(groups.max())
        for group in [first] if first == last else np.unique(groups).tolist():
            take = slice(None) if first == last else groups == group
            fronts = self.kept[group][1]
            size = fronts.shape[1]
            stacked = (self.slot[parent[take]] * size)[:, None] + within[take]  # rows of the stack
            out[take] = fronts.take(stacked[:, :, None] * size + within[take][:, None, :])


def selected_inverse(factor: SupernodalFactor, columns: np.ndarray) -> SelectedInverse:
    """Σ = (L Lᵀ)⁻¹ in L's pattern, computed in the supernodes that hold ``columns`` and their
    ancestors, with BLAS on one thread (numpy's OpenBLAS 0.3.31 crashed on two, in the
    products of a factor with a 16,389-column front: ``docs/architecture.md``)."""
    with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
        return _selected_inverse(factor, columns)


def _selected_inverse(factor: SupernodalFactor, columns: np.ndarray) -> SelectedInverse:
    needed = factor.path_to_root(columns)
    shapes = np.stack([factor.depth[needed], factor.width[needed], factor.height[needed]])
    keys, group = np.unique(shapes, axis=1, return_inverse=True)
    group = group.ravel()
    in_order = needed[np.argsort(group, kind="stable")]  # by group; a group's sorted within
    sizes = factor.height[in_order] * factor.width[in_order]
    offset = np.full(factor.first.size, -1)
    offset[in_order] = np.cumsum(sizes) - sizes
    buffer = np.empty(int(sizes.sum()))
    fronts = _Fronts(factor, needed)
    for index, (depth, width, height) in enumerate(keys.T.tolist()):  # from the root down
        supernodes = needed[group == index]
        lower = _lower_blocks(factor, supernodes, height, width)
        diagonal_inverse = _triangular_inverse(lower[:, :width])  # L_CC⁻¹
        front = np.empty((supernodes.size, height, height))
        front[:, :width, :width] = _gram_of_lower(diagonal_inverse)
        if height > width:
            first_entries = factor._indptr[factor.first[supernodes]]
            rows = factor._indices[first_entries[:, None] + np.arange(width, height)]
            fronts.lower_right(supernodes, rows, front[:, width:, width:])  # Σ_RR
            u = _times_lower(lower[:, width:], diagonal_inverse)
            front[:, width:, :width] = -front[:, width:, width:] @ u  # Σ_RC
            front[:, :width, :width] -= np.swapaxes(u, 1, 2) @ front[:, width:, :width]
            front[:, :width, width:] = np.swapaxes(front[:, width:, :width], 1, 2)
        start = offset[supernodes[0]]
        stacked = buffer[start : start + supernodes.size * height * width]
        stacked.reshape(supernodes.size, height, width)[...] = front[:, :, :width]
        fronts.keep(index, depth, supernodes, front)
    return SelectedInverse(factor, buffer, offset)


def inverse_blocks(factor: SupernodalFactor, groups: np.ndarray) -> np.ndarray:
    """The blocks (L Lᵀ)⁻¹[g, g], (G, c, c), for G groups g of c column indices (G, c), every
    pair of which must lie in L's pattern (``ValueError`` otherwise)."""
    inverse = selected_inverse(factor, groups.ravel())
    count, size = groups.shape
    a, b = np.tril_indices(size)  # a block is symmetric: its lower triangle is looked up
    rows, columns = groups[:, a].ravel(), groups[:, b].ravel()
    lower = inverse.entries(np.maximum(rows, columns), np.minimum(rows, columns))
    blocks = np.empty((count, size, size))
    blocks[:, a, b] = blocks[:, b, a] = lower.reshape(count, a.size)
    return blocks
