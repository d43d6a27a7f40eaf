"""The linear solvers of the normal equations, by name: ``cholmod`` and ``scipy`` (sparse
Cholesky, ``cholesky``) and ``cg`` (conjugate gradients, ``iterative``); "auto" is CHOLMOD where
cvxopt imports, else scipy, and conjugate gradients where CHOLMOD's factor would fill
(``iterative.FLOPS_PER_ENTRY``)."""

from __future__ import annotations

import numpy as np

from .cholesky import Appended, CholmodCholesky, ScipyCholesky
from .cvxopt_import import import_cholmod
from .iterative import FLOPS_PER_ENTRY, ConjugateGradients

BACKENDS = {"cholmod": CholmodCholesky, "scipy": ScipyCholesky, "cg": ConjugateGradients}


def available_backends() -> list[str]:
    """The direct backends that import here, fastest first."""
    names = []
    try:
        import_cholmod()
        names.append("cholmod")
    except ImportError:
        pass
    names.append("scipy")
    return names


def resolve_backend(backend: str) -> str:
    """The backend that ``backend`` names, "auto" being the fastest direct one available;
    ``ValueError`` if it is unknown or not available here."""
    if backend == "auto":
        return available_backends()[0]
    if backend not in BACKENDS:
        choices = ", ".join(BACKENDS)
        raise ValueError(f"unknown linear solver {backend!r}; choose from auto, {choices}")
    if backend != "cg" and backend not in available_backends():
        raise ValueError(f"backend {backend!r} is not available here (is cvxopt installed?)")
    return backend


def inverts_selectively(backend: str) -> bool:
    """Whether ``backend``'s covariance blocks of many groups come from selected inversion, at
    about the cost of a factorisation, rather than from a solve per group."""
    return BACKENDS[resolve_backend(backend)].inverts_selectively


def make_cholesky(
    indices: np.ndarray,
    indptr: np.ndarray,
    size: int,
    backend: str = "auto",
    for_covariance: bool = False,
    previous=None,
    appended: Appended | None = None,
    diagonal_blocks: np.ndarray | None = None,
):
    """A factoriser for the symmetric CSC pattern (both triangles stored, sorted indices);
    ``for_covariance`` prepares it for ``covariance_blocks`` (a direct one). ``previous``, a
    factoriser for a pattern this one grew from (as ``appended`` says, where known), may speed
    up the set-up. ``diagonal_blocks``, where the CSC data holds the nodes' diagonal blocks
    (``BlockLayout.diagonal_blocks``), precondition conjugate gradients."""
    if backend == "cg" and not for_covariance:
        direct = available_backends()[0]
        return ConjugateGradients(
            indices,
            indptr,
            size,
            lambda: make_cholesky(indices, indptr, size, direct),
            diagonal_blocks,
        )
    name = resolve_backend("auto" if backend == "cg" else backend)
    if name == "scipy":
        return ScipyCholesky(indices, indptr, size)
    previous = getattr(previous, "direct", previous)
    grown_from = previous if isinstance(previous, CholmodCholesky) else None
    cholmod = CholmodCholesky(indices, indptr, size, for_covariance, grown_from, appended)
    if backend == "auto" and not for_covariance and _fills(cholmod, indices.size):
        return ConjugateGradients(indices, indptr, size, lambda: cholmod, diagonal_blocks)
    return cholmod


def predicted_flops_per_entry(cholmod: CholmodCholesky, entries: int) -> float | None:
    """CHOLMOD's predicted factorisation flops (``CholmodCholesky.predicted_flops``) per stored
    entry of the lower triangle, about half of ``entries`` (both triangles' count); None where
    they cannot be read."""
    flops = cholmod.predicted_flops()
    return None if flops is None else flops / (0.5 * entries)


def _fills(cholmod: CholmodCholesky, entries: int) -> bool:
    """Whether CHOLMOD's factorisation would take more than ``FLOPS_PER_ENTRY`` flops per stored
    entry (``predicted_flops_per_entry``); not read where even a dense factor's n³/3 would not."""
    if cholmod.size**3 / 3.0 <= FLOPS_PER_ENTRY * 0.5 * entries:
        return False
    per_entry = predicted_flops_per_entry(cholmod, entries)
    return per_entry is not None and per_entry > FLOPS_PER_ENTRY
