"""Sparse Cholesky backends for a fixed sparsity pattern: analyse once, factorise many times.

* ``cholmod``: SuiteSparse CHOLMOD through the cvxopt wheel (AMD ordering; supernodal LLᵀ, or
  simplicial LDLᵀ where CHOLMOD finds the factor too sparse for supernodes), given the lower
  triangle; the faster of the two. Covariances of many columns by selected inversion of its
  supernodal factor.
* ``scipy``: SuperLU in symmetric mode with a minimum-degree ordering computed once and reused
  (``permc_spec="NATURAL"`` on the pre-permuted matrix). Pure scipy, always available.

``posegraph.problem.backends`` chooses among them (and conjugate gradients, ``iterative``).
A matrix that is not positive definite raises ``NotPositiveDefinite``. Both give each column's
pivot (``pivots``): dⱼ of P A Pᵀ = L D Lᵀ (L unit lower triangular), the Schur complement's
diagonal entry where column j is eliminated. dⱼ/Aⱼⱼ near zero marks a column that the columns
eliminated before it nearly span.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from .cvxopt_import import import_cholmod
from .factor_size import predicted_flops
from .selected_inversion import SupernodalFactor, inverse_blocks

if TYPE_CHECKING:
    import scipy.sparse

SIMPLICIAL, AUTO, SUPERNODAL = 0, 1, 2
"""cvxopt's values of CHOLMOD's ``supernodal`` option (``CHOLMOD_SIMPLICIAL`` …)."""

SOLVED_COLUMNS = 96
"""CHOLMOD's covariance blocks of up to this many columns in all come from solves, beyond from
selected inversion, near where the two draw level (docs/architecture.md)."""


COUPLED_COLUMNS = 300
"""Selected inversion needs every pair of a group's columns in the factor's pattern, which makes
a group of c columns a dense c × c block there, at c³/3 flops. Groups larger than this come
from solves, whose cost grows linearly."""


LONG_COLUMN = 64
"""Columns of more entries than this count as long when a CHOLMOD pattern is built."""

LONG_COLUMN_COST = 30
"""``ones_at`` builds the long columns transposed when the sum of their squared lengths exceeds
this many times the number of entries: where the two ways broke even, measured here."""


def builds_transposed(counts: np.ndarray) -> np.ndarray:
    """Which columns of these entry ``counts`` ``ones_at`` builds transposed."""
    long = counts > LONG_COLUMN
    if np.sum(counts[long] ** 2) <= LONG_COLUMN_COST * np.sum(counts):
        return np.zeros_like(long)
    return long


def covariance_by_solves(columns: int, largest_group: int) -> bool:
    """Whether covariance blocks of ``columns`` columns in all, at most ``largest_group`` in one
    group, come from solves rather than selected inversion."""
    return columns <= SOLVED_COLUMNS or largest_group > COUPLED_COLUMNS


def ones_at(rows: np.ndarray, columns: np.ndarray, shape: tuple[int, int]):
    """The cvxopt sparse matrix of ones at (``rows``, ``columns``), each pair once, stored
    in column order with sorted rows.

    cvxopt's triplet constructor compares each entry with every slot of its column (to sum
    duplicates), which is quadratic in a column's length. A node that thousands of edges reach
    (an anchor every pose is tied to) makes such columns: a 4000-pose SE3 graph spent 1.05 of
    its 1.18 s there. When the long columns' quadratic cost outweighs one sparse addition (linear
    in all entries; ``builds_transposed``), those columns are built transposed, where they are
    short rows, transposed back and added."""
    from cvxopt import matrix, spmatrix

    def triplets(r: np.ndarray, c: np.ndarray, size: tuple[int, int]):
        return spmatrix(1.0, matrix(r, tc="i"), matrix(c, tc="i"), size)

    transposed = builds_transposed(np.bincount(columns, minlength=shape[1]))[columns]
    if not transposed.any():
        return triplets(rows, columns, shape)
    return (
        triplets(rows[~transposed], columns[~transposed], shape)
        + triplets(columns[transposed], rows[transposed], shape[::-1]).T
    )


@dataclasses.dataclass(frozen=True)
class Appended:
    """How a symmetric CSC pattern extends an earlier one whose rows and columns it keeps first:
    each earlier entry's position now (``relocated``), and the positions of the entries
    inserted, sorted, each in a row or column past the earlier size."""

    relocated: np.ndarray
    inserted: np.ndarray


class NotPositiveDefinite(ArithmeticError):
    """The matrix could not be factorised (not positive definite, or singular)."""


def dense_inverse_form(
    solve, size: int, rows: np.ndarray, columns: np.ndarray, values: np.ndarray, count: int
) -> np.ndarray:
    """Bᵀ A⁻¹ B, (count, count), for the B (size, count) of the entries given (repeated ones
    add up), by one ``solve`` (A⁻¹ of columns) of B's dense columns."""
    b = np.zeros((size, count))
    np.add.at(b, (rows, columns), values)
    return b.T @ solve(b)


class CholmodCholesky:
    """CHOLMOD (cvxopt) with the symbolic factorisation computed once for the pattern."""

    name = "cholmod"
    inverts_selectively = True

    def __init__(
        self,
        indices: np.ndarray,
        indptr: np.ndarray,
        size: int,
        supernodal: bool = False,
        previous: CholmodCholesky | None = None,
        appended: Appended | None = None,
    ) -> None:
        """``supernodal`` forces an LLᵀ factor (CHOLMOD may otherwise pick LDLᵀ: ``_analyse``),
        which ``covariance_blocks`` needs. ``previous`` is a factoriser for a leading part of this
        pattern, or for the same one (see ``_lower_pattern``); ``appended`` says how this
        pattern extends it, where known."""
        cholmod = import_cholmod()
        from cvxopt import matrix, spmatrix

        self._cholmod, self._matrix, self._spmatrix = cholmod, matrix, spmatrix
        self.size = size
        self._supernodal = supernodal
        # CHOLMOD reads the lower triangle only (uplo="L"): passing just that halves the
        # triplets cvxopt sorts into its matrix and the values copied per factorisation.
        if previous is not None and appended is not None:
            columns = np.searchsorted(indptr, appended.inserted, side="right") - 1
            rows = indices[appended.inserted]
            lower = rows >= columns
            added, kept = appended.inserted[lower], appended.relocated[previous._lower]
            self._lower = np.insert(kept, np.searchsorted(kept, added), added)
            self._a = self._extended_pattern(rows[lower], columns[lower], previous)
        else:
            columns = np.repeat(np.arange(size), np.diff(indptr))
            self._lower = np.flatnonzero(indices >= columns)
            self._a = self._lower_pattern(indices[self._lower], columns[self._lower], previous)
        self._factor = self._analyse()

    def _analyse(self):
        """CHOLMOD's symbolic factorisation of the pattern: supernodal LLᵀ if asked for, else
        CHOLMOD's own choice (``CHOLMOD_AUTO``: simplicial LDLᵀ below 40 flops per entry of L,
        where a supernode's dense kernels cost more than they save; cvxopt asks for
        supernodal always unless told)."""
        cholmod = self._cholmod
        saved = dict(cholmod.options)
        cholmod.options["supernodal"] = SUPERNODAL if self._supernodal else AUTO
        try:
            return cholmod.symbolic(self._a)
        finally:
            cholmod.options.clear()
            cholmod.options.update(saved)

    def _lower_pattern(self, rows: np.ndarray, columns: np.ndarray, previous):
        """The cvxopt matrix of the lower-triangle pattern (ones). If ``previous`` holds its
        leading n₀ × n₀ part unchanged (a graph that grew by appended nodes and edges between
        them or to old nodes), the new rows and columns are concatenated to it, which skips
        cvxopt's triplet sort of the whole pattern."""
        size = self.size
        n0 = previous.size if previous is not None else 0
        old = (rows < n0) & (columns < n0)
        if not (0 < n0 <= size and np.count_nonzero(old) == previous._lower.size):
            return ones_at(rows, columns, (size, size))
        return self._extended_pattern(rows[~old], columns[~old], previous)

    def _extended_pattern(self, rows: np.ndarray, columns: np.ndarray, previous):
        """The cvxopt lower-triangle pattern of ``previous``'s with the entries (``rows``,
        ``columns``) added, each in a row or column past its size."""
        from cvxopt import sparse

        size, n0 = self.size, previous.size
        if n0 == size:  # the same pattern: its matrix is shared (values are set per use)
            return previous._a
        # ``sparse`` drops explicit zeros; previous's values are placeholders between
        # factorisations, so they are set to ones.
        previous._a.V = self._matrix(1.0, (previous._lower.size, 1))
        below, right, k = columns < n0, columns >= n0, size - n0
        return sparse(
            [
                [previous._a, ones_at(rows[below] - n0, columns[below], (k, n0))],
                [
                    ones_at(rows[:0], rows[:0], (n0, k)),
                    ones_at(rows[right] - n0, columns[right] - n0, (k, k)),
                ],
            ]
        )

    def factorize(self, data: np.ndarray) -> None:
        if self._factor is None:
            self._factor = self._analyse()
        self._a.V = self._matrix(data[self._lower])
        try:
            self._cholmod.numeric(self._a, self._factor)
        except ArithmeticError as error:
            raise NotPositiveDefinite(str(error)) from None
        # LDLᵀ factorises indefinite matrices too, LLᵀ does not. A denormal d > 0 gives 1/d = ∞.
        if not self._is_supernodal() and not np.all(self._d_inverse() > 0):
            raise NotPositiveDefinite("a pivot ≤ 0 in CHOLMOD's LDLᵀ factorisation")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve for a vector (n,) or for every column of (n, k) at once."""
        b = self._matrix(np.ascontiguousarray(rhs, float))
        self._cholmod.solve(self._factor, b)
        return np.array(b).reshape(np.shape(rhs))

    def predicted_flops(self) -> float | None:
        """About the flops of a numeric factorisation, from the symbolic analysis
        (``factor_size``); None where it cannot be read."""
        if self._factor is None:
            self._factor = self._analyse()
        return predicted_flops(self._factor, self.size)

    def covariance_blocks(self, groups: np.ndarray) -> np.ndarray:
        """Blocks (A⁻¹)[g, g], (G, c, c), for G groups g of c columns (G, c): by sparse solves
        (their cost grows with each column), or, as ``covariance_by_solves`` decides and if this
        factoriser was made ``supernodal`` (P A Pᵀ = L Lᵀ, so A⁻¹ = Pᵀ (L Lᵀ)⁻¹ P), by
        selected inversion of L (whose cost does not), for groups whose every pair lies in
        A's pattern."""
        if self._supernodal and not covariance_by_solves(groups.size, groups.shape[1]):
            return self._selected_blocks(groups)
        return self._solved_blocks(groups)

    def inverse_form(
        self, rows: np.ndarray, columns: np.ndarray, values: np.ndarray, count: int
    ) -> np.ndarray:
        """Bᵀ A⁻¹ B, (count, count), for the sparse B (size, count) of the entries given (rows,
        columns, values; repeated ones add up): sparse solves, whose cost follows the paths of
        B's rows in the elimination tree, not the factor's size (``_half_solved``)."""
        b = self._spmatrix(values.tolist(), rows.tolist(), columns.tolist(), (self.size, count))
        y, scaled = self._half_solved(b)
        return (y.T @ scaled).toarray()

    def _half_solved(self, b) -> tuple:
        """Y = L⁻¹ P B and D⁻¹ Y (P A Pᵀ = L D Lᵀ, D = I for a supernodal factor), as scipy
        CSC matrices, by sparse solves with the cvxopt sparse matrix B: Bᵀ A⁻¹ B = Yᵀ D⁻¹ Y."""
        import scipy.sparse  # on use: a solve with CHOLMOD does without scipy

        y = self._cholmod.spsolve(self._factor, b, sys=7)  # P
        y = self._cholmod.spsolve(self._factor, y, sys=4)  # L⁻¹
        scaled = self._cholmod.spsolve(self._factor, y, sys=6)  # D⁻¹
        return tuple(scipy.sparse.csc_matrix(self._compressed(m), m.size) for m in (y, scaled))

    def _solved_blocks(self, groups: np.ndarray) -> np.ndarray:
        """Each block as Yᵀ D⁻¹ Y with Y = L⁻¹ P E_g (``_half_solved`` of the unit columns),
        for a factor of either kind."""
        columns = groups.ravel()
        unit = self._spmatrix(
            1.0, columns.tolist(), list(range(columns.size)), (self.size, columns.size)
        )
        y, scaled = self._half_solved(unit)
        width = groups.shape[1]
        parts = [slice(g * width, (g + 1) * width) for g in range(len(groups))]
        return np.array([(y[:, part].T @ scaled[:, part]).toarray() for part in parts])

    def _places(self) -> np.ndarray:
        """Where P A Pᵀ puts each column of A."""
        columns = self._matrix(np.arange(self.size, dtype=float))
        self._cholmod.solve(self._factor, columns, sys=8)  # Pᵀ
        return np.array(columns).ravel().astype(np.int64)

    def _selected_blocks(self, groups: np.ndarray) -> np.ndarray:
        """The blocks from the selected inverse of L (``posegraph.problem.selected_inversion``).
        Reading L out (cvxopt's ``getfactor``) leaves CHOLMOD's factor spent: the next
        ``factorize`` analyses the pattern afresh."""
        place = self._places()
        data, indices, indptr = self._compressed(self._cholmod.getfactor(self._factor))
        self._factor = None
        return inverse_blocks(SupernodalFactor(indptr, indices, data), place[groups])

    def pivots(self) -> np.ndarray:
        """Per column of A, its pivot in the last factorisation (``pivots``): L's diagonal
        squared for a supernodal factor (P A Pᵀ = L Lᵀ), D for a simplicial one (L D Lᵀ)."""
        if self._is_supernodal():
            in_factor = np.array(self._cholmod.diag(self._factor)).ravel() ** 2
        else:
            in_factor = 1.0 / self._d_inverse()
        return in_factor[self._places()]

    def _is_supernodal(self) -> bool:
        """Whether CHOLMOD's factor is supernodal LLᵀ (``diag`` reads only those), not LDLᵀ."""
        try:
            self._cholmod.diag(self._factor)
        except ValueError:
            return False
        return True

    def _d_inverse(self) -> np.ndarray:
        """D⁻¹ 1 of a simplicial P A Pᵀ = L D Lᵀ, in factor order."""
        inverse = self._matrix(1.0, (self.size, 1))
        self._cholmod.solve(self._factor, inverse, sys=6)
        return np.array(inverse).ravel()

    @staticmethod
    def _compressed(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(data, indices, indptr) of a cvxopt sparse matrix's compressed columns: views of the
        copy that ``CCS`` makes (the factor of a 50,000-pose sphere took 2.8 s and two more
        copies through ``numpy.array``), not of ``matrix``."""
        indptr, indices, data = (np.asarray(part).ravel() for part in matrix.CCS)
        return data, indices.astype(np.int64, copy=False), indptr.astype(np.int64, copy=False)


class ScipyCholesky:
    """SuperLU (symmetric mode, no pivoting). The first factorisation chooses a minimum-degree
    ordering, and its factor serves; later ones factorise the matrix permuted by that ordering,
    with no ordering work."""

    name = "scipy"
    inverts_selectively = False
    _OPTIONS = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}

    def __init__(self, indices: np.ndarray, indptr: np.ndarray, size: int) -> None:
        self._indices, self._indptr, self._size = indices, indptr, size
        self._order: np.ndarray | None = None
        self._gather = self._permuted_indices = self._permuted_indptr = None
        self._lu = None
        self._factors_permuted = False
        """Whether ``_lu`` factorises A[order][:, order] (else A, with its own ordering)."""

    def _matrix(self, data, indices, indptr) -> scipy.sparse.csc_matrix:
        import scipy.sparse

        return scipy.sparse.csc_matrix((data, indices, indptr), shape=(self._size, self._size))

    def _fix_ordering(self, order: np.ndarray) -> None:
        """Factorise A[order][:, order] from now on: its column k is A's column ``order[k]``."""
        entries = np.arange(1, self._indices.size + 1, dtype=float)
        permuted = self._matrix(entries, self._indices, self._indptr)[order][:, order].tocsc()
        permuted.sort_indices()
        self._order = order
        self._gather = permuted.data.astype(np.int64) - 1
        self._permuted_indices, self._permuted_indptr = permuted.indices, permuted.indptr

    def factorize(self, data: np.ndarray) -> None:
        import scipy.sparse.linalg  # on use: where CHOLMOD serves, a start does without it

        try:
            if self._order is None:
                matrix = self._matrix(data, self._indices, self._indptr)
                lu = scipy.sparse.linalg.splu(matrix, permc_spec="MMD_AT_PLUS_A", **self._OPTIONS)
                # SuperLU's perm_c sends A's column j to position perm_c[j].
                self._fix_ordering(np.argsort(lu.perm_c))
                self._factors_permuted = False
            else:
                permuted = data[self._gather]
                matrix = self._matrix(permuted, self._permuted_indices, self._permuted_indptr)
                lu = scipy.sparse.linalg.splu(matrix, permc_spec="NATURAL", **self._OPTIONS)
                self._factors_permuted = True
        except RuntimeError as error:
            raise NotPositiveDefinite(str(error)) from None
        self._lu = lu
        if np.any(lu.U.diagonal() <= 0):
            raise NotPositiveDefinite("non-positive pivot")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if not self._factors_permuted:
            return self._lu.solve(rhs)
        x = np.empty_like(rhs)
        x[self._order] = self._lu.solve(rhs[self._order])
        return x

    def pivots(self) -> np.ndarray:
        """Per column, its pivot in the last factorisation (``pivots``): U's diagonal, whose
        entry k is that of the column the ordering puts k-th (either factor)."""
        pivots = np.empty(self._size)
        pivots[self._order] = self._lu.U.diagonal()
        return pivots

    def inverse_form(
        self, rows: np.ndarray, columns: np.ndarray, values: np.ndarray, count: int
    ) -> np.ndarray:
        """Bᵀ A⁻¹ B, (count, count), for the B (size, count) of the entries given (repeated
        ones add up), by one solve of its columns."""
        return dense_inverse_form(self.solve, self._size, rows, columns, values, count)

    def covariance_blocks(self, groups: np.ndarray) -> np.ndarray:
        """Blocks (A⁻¹)[g, g], (G, c, c), by solving for the unit columns of each group."""
        blocks = np.empty(groups.shape + groups.shape[1:])
        unit = np.zeros((self._size, groups.shape[1]))
        for block, group in zip(blocks, groups, strict=True):
            unit[group, np.arange(group.size)] = 1.0
            block[:] = self.solve(unit)[group]
            unit[group, np.arange(group.size)] = 0.0
        return blocks
