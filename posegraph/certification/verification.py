"""The certificate of a critical point Y of SE-Sync's rank-restricted problem (Rosen et al. 2019,
Theorem 7 and §4.2): the Lagrange multipliers Λ = SymBlockDiag(Yᵀ Y Q) of the first-order
conditions, and the smallest eigenvalue of S = Q − Λ. S ⪰ 0 certifies that YᵀY solves the
semidefinite relaxation; where Y has rank d, its rounding is then the global optimum."""

from __future__ import annotations

import dataclasses
import warnings
from typing import TYPE_CHECKING

import numpy as np

from .data import SESyncData
from .stiefel import blocks, sym_block_products

if TYPE_CHECKING:
    import scipy.sparse.linalg

EIGEN_TOLERANCE = 1e-5
"""Relative residual at which LOBPCG stops."""
EIGEN_ITERATIONS = 500
"""Most LOBPCG iterations."""


@dataclasses.dataclass(frozen=True)
class Spectrum:
    """The check of S = Q − Λ against a tolerance δ: whether S + δI ≻ 0, and λ_min(S) with its
    eigenvector (dn,) where that fails. Where it holds, ``smallest`` is S's smallest Rayleigh
    quotient on Y's rows (its null space at a critical point), which λ_min(S) lies between −δ
    and, and ``vector`` is None."""

    certified: bool
    smallest: float
    vector: np.ndarray | None


def multipliers(data: SESyncData, y: np.ndarray) -> np.ndarray:
    """Λ's diagonal blocks (n, d, d): Sym(Yᵢᵀ (Y Q)ᵢ)."""
    return sym_block_products(y, data.product(y), data.d)


def certificate_matrix(data: SESyncData, lam: np.ndarray) -> scipy.sparse.linalg.LinearOperator:
    """S = Q − Λ as an operator on dn-vectors and blocks of them (Λ's blocks ``lam``)."""
    import scipy.sparse.linalg  # on use: commands that do not certify do without scipy

    d, size = data.d, data.d * data.n

    def apply(x: np.ndarray) -> np.ndarray:
        columns = np.asarray(x).reshape(size, -1)
        qx = data.product(columns.T).T
        return qx - (lam @ columns.reshape(-1, d, columns.shape[1])).reshape(size, -1)

    return scipy.sparse.linalg.LinearOperator(
        (size, size), matvec=lambda x: apply(x)[:, 0], matmat=apply, dtype=float
    )


def _on_rows(s, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(an orthonormal basis of Y's rows, S's eigenvalues and eigenvectors on it)."""
    basis = np.linalg.qr(y.T)[0]
    values, vectors = np.linalg.eigh(basis.T @ s.matmat(basis))
    return basis, values, vectors


def check(data: SESyncData, y: np.ndarray, tolerance: float) -> Spectrum:
    """Whether S + δI ≻ 0 (δ = ``tolerance``): S is the Schur complement of the sparse matrix
    ``SESyncData.joint`` with Λ subtracted from its rotation block onto that block, so a sparse
    Cholesky factorisation of that matrix plus δI on the rotations succeeds exactly when it
    holds (Rosen et al. 2019, §4.2, and the Schur complement lemma). Where it fails, λ_min(S)
    and its eigenvector come from ``smallest_eigenpair``."""
    lam = multipliers(data, y)
    s = certificate_matrix(data, lam)
    if data.factor_less(lam, tolerance) is None:
        return smallest_eigenpair(data, y, s)
    return Spectrum(True, float(_on_rows(s, y)[1][0]), None)


def smallest_eigenpair(data: SESyncData, y: np.ndarray, s, seed: int = 0) -> Spectrum:
    """λ_min(S) and its eigenvector (a failed check; ``s``: S as ``certificate_matrix``). At a
    critical point S Yᵀ = 0, so the rows of Y span eigenvectors of eigenvalue 0, and the rest of
    the spectrum is found by LOBPCG (Knyazev 2001) on their orthogonal complement,
    preconditioned by ``SESyncData.precondition``, from seeded random vectors."""
    import scipy.sparse.linalg

    size = s.shape[0]
    basis, on_values, on_vectors = _on_rows(s, y)
    preconditioner = scipy.sparse.linalg.LinearOperator(
        (size, size),
        matvec=lambda x: data.precondition(np.asarray(x).reshape(1, -1))[0],
        matmat=lambda x: data.precondition(np.asarray(x).T).T,
    )
    start = np.random.default_rng(seed).normal(size=(size, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "not reaching the requested tolerance"
        values, vectors = scipy.sparse.linalg.lobpcg(
            s,
            start,
            M=preconditioner,
            Y=basis,
            largest=False,
            tol=EIGEN_TOLERANCE,
            maxiter=EIGEN_ITERATIONS,
        )
    if on_values[0] < values[0]:
        return Spectrum(False, float(on_values[0]), basis @ on_vectors[:, 0])
    return Spectrum(False, float(values[0]), vectors[:, 0])


def rounded(y: np.ndarray, d: int) -> np.ndarray:
    """Rotations R (d × dn) from Y (r × dn): the rank-d part of Y's SVD, Σ_d V_dᵀ, reflected
    if most of its blocks have negative determinant, each block then projected onto SO(d)
    (SE-Sync Algorithm 2)."""
    _, singular, vt = np.linalg.svd(y, full_matrices=False)
    r_hat = singular[:d, None] * vt[:d]
    parts = blocks(r_hat, d)
    if np.count_nonzero(np.linalg.det(parts) > 0) < parts.shape[0] / 2:
        r_hat[-1] *= -1.0
        parts = blocks(r_hat, d)
    u, _, wt = np.linalg.svd(parts)
    signs = np.ones((parts.shape[0], d))
    signs[:, -1] = np.sign(np.linalg.det(u @ wt))
    rotations = (u * signs[:, None, :]) @ wt
    return rotations.transpose(1, 0, 2).reshape(d, -1)
