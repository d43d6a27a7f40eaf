"""Conjugate gradients in place of a Cholesky factorisation whose factor would fill: the
normal equations of a pose graph with many long loops (false loop closures drawn anywhere in
the map make its graph an expander) fill their factor almost densely, and the same long loops
make the matrix well conditioned, so that conjugate gradients preconditioned by the nodes'
diagonal blocks (block Jacobi, as Ceres's ``JACOBI`` preconditioner) converge in a few hundred
products with the matrix (Hestenes & Stiefel 1952; g2o's and Ceres' iterative linear solvers
serve the same case).

The matrix is kept, not factorised. A solve that does not reach ``RELATIVE_RESIDUAL`` within
``MAX_ITERATIONS`` falls back to the direct factoriser given, which then also gives what only a
factor can: pivots, covariance blocks, and ``NotPositiveDefinite`` for a singular matrix.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .cholesky import NotPositiveDefinite

FLOPS_PER_ENTRY = 1e5
""""auto" takes conjugate gradients where CHOLMOD's factorisation would take more than this many
flops per stored entry of the matrix (``factor_size.predicted_flops``): a product with the
matrix costs about 4 flops per entry of its lower triangle, at roughly a fortieth of the rate
of the factorisation's dense kernels, so this is the cost of about 600 iterations."""
RELATIVE_RESIDUAL = 1e-10
"""A solve ends when ‖A x − b‖ ≤ this × ‖b‖: about the accuracy of a direct solve of a well
conditioned system, so that a solver's steps and decisions do not change."""
MAX_ITERATIONS = 3000
"""Iterations before a solve falls back to the direct factoriser."""
FEW_COLUMNS = 3
"""Right-hand sides of up to this many columns (the chordal relaxation's d rows of the
rotations) are solved column by column; more (leverage's probes) by the direct factoriser,
which a filling factor makes cost some twenty conjugate-gradient solves (docs/benchmarks.md)."""


class ConjugateGradients:
    """Preconditioned conjugate gradients (scipy's ``cg``, the block-Jacobi preconditioner)
    over the symmetric CSC pattern (both triangles, sorted indices); ``diagonal_blocks``, where
    its data holds the nodes' diagonal blocks (k, d, d), by default the diagonal's entries
    (Jacobi); ``direct`` makes the factoriser that a solve falls back to, on first need."""

    name = "cg"
    inverts_selectively = False

    def __init__(
        self,
        indices: np.ndarray,
        indptr: np.ndarray,
        size: int,
        direct: Callable[[], object],
        diagonal_blocks: np.ndarray | None = None,
    ) -> None:
        self.size = size
        self._indices, self._indptr = indices, indptr
        if diagonal_blocks is None:
            columns = np.repeat(np.arange(size), np.diff(indptr))
            diagonal_blocks = np.flatnonzero(indices == columns)[:, None, None]
        self._diagonal_blocks = diagonal_blocks
        self._make_direct, self._direct = direct, None
        self._data: np.ndarray | None = None
        self._factorised = False
        """Whether the direct factoriser holds ``_data``'s factor."""

    def factorize(self, data: np.ndarray) -> None:
        """Keep the matrix; nothing is factorised until a solve needs it."""
        self._data, self._factorised = data, False

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve for a vector (n,) or for (n, k) columns by conjugate gradients, column by
        column, up to ``FEW_COLUMNS``; more columns (leverage's probes) by the direct
        factoriser, whose factorisation serves them all (each column after it two triangular
        solves), as does a solve that does not converge."""
        rhs = np.asarray(rhs, dtype=float)
        columns = rhs.reshape(self.size, -1)
        if self._factorised or columns.shape[1] > FEW_COLUMNS:
            return self._factor().solve(rhs)
        solution = self._iterate(columns)
        if solution is None:
            return self._factor().solve(rhs)
        return solution.reshape(rhs.shape)

    def inverse_form(
        self, rows: np.ndarray, columns: np.ndarray, values: np.ndarray, count: int
    ) -> np.ndarray:
        """Bᵀ A⁻¹ B for the sparse B of the entries given, by the direct factoriser (as for
        several columns: ``solve``)."""
        return self._factor().inverse_form(rows, columns, values, count)

    def _iterate(self, b: np.ndarray) -> np.ndarray | None:
        """The preconditioned conjugate-gradient solution X of A X = B for (n, k) columns B,
        one column at a time, or None where one does not converge (or a diagonal block is not
        positive definite: nor is A)."""
        import scipy.sparse
        import scipy.sparse.linalg

        if self._diagonal_blocks.size != self.size * self._diagonal_blocks.shape[-1]:
            return None  # the pattern lacks a diagonal entry
        blocks = self._data[self._diagonal_blocks]
        try:
            np.linalg.cholesky(blocks)
        except np.linalg.LinAlgError:
            return None
        matrix = scipy.sparse.csc_array(
            (self._data, self._indices, self._indptr), shape=(self.size, self.size)
        )
        count = len(blocks)
        preconditioner = scipy.sparse.bsr_array(
            (np.linalg.inv(blocks), np.arange(count), np.arange(count + 1)),
            shape=(self.size, self.size),
        )
        solution = np.empty_like(b)
        for k, column in enumerate(b.T):
            x, info = scipy.sparse.linalg.cg(
                matrix,
                column,
                rtol=RELATIVE_RESIDUAL,
                atol=0.0,
                maxiter=MAX_ITERATIONS,
                M=preconditioner,
            )
            if info != 0 or not np.all(np.isfinite(x)):
                return None
            solution[:, k] = x
        return solution

    def _factor(self):
        """The direct factoriser, factorising the kept matrix (``NotPositiveDefinite`` if it is
        not positive definite)."""
        if self._direct is None:
            self._direct = self._make_direct()
        if not self._factorised:
            self._direct.factorize(self._data)
            self._factorised = True
        return self._direct

    def pivots(self) -> np.ndarray:
        """The direct factoriser's pivots of the kept matrix (where it is not positive definite,
        those of the factorisation that failed, as a direct factoriser gives them)."""
        try:
            return self._factor().pivots()
        except NotPositiveDefinite:
            return self._direct.pivots()

    def covariance_blocks(self, groups: np.ndarray) -> np.ndarray:
        """The direct factoriser's covariance blocks of the kept matrix."""
        return self._factor().covariance_blocks(groups)

    @property
    def direct(self):
        """The direct factoriser, if made (a grown pattern's factoriser starts from it)."""
        return self._direct
