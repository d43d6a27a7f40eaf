"""Checks of what enters a pose graph: node ids, group elements and information matrices, each
refusal naming what is wrong; and the information's ranks and start-node form."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from ..lie import LieGroup


def node_id_array(node_ids: Iterable[int] | np.ndarray | int) -> np.ndarray:
    """Node ids as a 1-D int64 array. Whole floats (ids loaded with ``numpy.loadtxt``) are
    taken; anything else that is not an integer of at most 64 bits, or ids nested in more than
    one dimension, is refused with a ``ValueError`` naming the first offending id."""
    given = np.atleast_1d(np.asarray(node_ids))
    if given.ndim != 1:
        raise ValueError(f"node ids are one sequence of integers, not of shape {given.shape}")
    kind = given.dtype.kind
    if kind == "i":
        whole = np.ones(given.shape, dtype=bool)
    elif kind == "u":
        whole = given < 2**63
    elif kind == "f":
        whole = (given == np.trunc(given)) & (-(2.0**63) <= given) & (given < 2.0**63)
    else:
        whole = np.array([type(k) is int and -(2**63) <= k < 2**63 for k in given.tolist()])
    if not whole.all():
        first = given[~whole].tolist()[0]
        raise ValueError(f"node id {first!r} is not an integer of at most 64 bits")
    return given.astype(np.int64)


LOOKED_UP = 64
"""``indices_of`` looks up to this many ids one by one in a dict; more are searched for among
the sorted node ids at once (a file's edge ends: one search, not a lookup each)."""


def indices_of(ids: np.ndarray, known: np.ndarray, index_of: dict[int, int]) -> np.ndarray:
    """Where each of ``ids`` lies among the distinct ``known`` node ids (``index_of`` maps each
    to its place); ``KeyError`` naming the first id not among them."""
    if ids.size > LOOKED_UP and known.size:
        order = np.argsort(known)
        found = order[np.searchsorted(known, ids, sorter=order).clip(max=known.size - 1)]
        unknown = known[found] != ids
        if unknown.any():
            raise KeyError(f"node {ids[unknown][0]} is not in the graph")
        return found
    try:
        return np.fromiter((index_of[k] for k in ids.tolist()), np.int64, ids.size)
    except KeyError as error:
        raise KeyError(f"node {error.args[0]} is not in the graph") from None


def named_nodes(node_ids: np.ndarray, shown: int = 3) -> str:
    """Node ids as a phrase: "node 4", or "nodes 4, 6, 8, … (20 nodes)" past ``shown``."""
    named = ", ".join(str(node) for node in node_ids[:shown])
    if len(node_ids) == 1:
        return f"node {named}"
    return f"nodes {named}" + (f", … ({len(node_ids)} nodes)" if len(node_ids) > shown else "")


LOG_DETERMINANT_LIMIT = 300.0
"""Largest |log det| of an element's linear block: a Sim3 scale within e^±100. Beyond it,
products of a few elements and the logarithm's series overflow or lose every digit (a scale
of e^355 makes ``Sim3.log`` return NaN); no trajectory's scale comes near."""


def element_problems(matrices: np.ndarray) -> tuple[np.ndarray, Callable[[int], str]]:
    """Which of (n, m, m) matrices cannot be group elements, and what the k-th has: a last
    entry other than 1 (by more than 1e-4), or a linear block whose determinant is not
    positive, or whose logarithm is beyond ±``LOG_DETERMINANT_LIMIT`` (NaN, for a matrix that
    is not finite, which callers refuse first)."""
    corner = matrices[:, -1, -1]
    with np.errstate(all="ignore"):
        determinant = np.linalg.det(matrices[:, :-1, :-1])
        log_determinant = np.log(determinant)
    unit_corner = np.abs(corner - 1) <= 1e-4
    positive = determinant > 0
    bad = ~unit_corner | ~positive | ~(np.abs(log_determinant) <= LOG_DETERMINANT_LIMIT)

    def why(k: int) -> str:
        if not unit_corner[k]:
            return f"a last entry of {corner[k]:.3g}, not 1"
        if not positive[k]:
            return f"determinant {determinant[k]:.3g}"
        return (
            f"determinant {determinant[k]:.3g}, beyond e^±{LOG_DETERMINANT_LIMIT:g}: a scale"
            " out of range"
        )

    return bad, why


def positive_definite(matrices: np.ndarray) -> np.ndarray:
    """Whether each of (n, d, d) symmetric matrices is positive definite. numpy's batched
    Cholesky answers for all at once where every one is, the usual case; otherwise a Gaussian
    elimination of all at once, column by column, tells which: every pivot (of the matrix
    scaled by its largest entry) positive and finite. Batched eigenvalues cost far more."""
    with np.errstate(all="ignore"):  # a pivot that overflows or is NaN fails the test
        reduced = np.array(matrices, dtype=float)
        reduced /= np.abs(reduced).max(axis=(1, 2), keepdims=True)  # definiteness is scale-free
        try:
            if np.isfinite(np.linalg.cholesky(reduced)).all():
                return np.ones(len(reduced), dtype=bool)
        except np.linalg.LinAlgError:
            pass
        positive = np.ones(len(reduced), dtype=bool)
        for k in range(reduced.shape[-1]):
            pivot = reduced[:, k, k]
            positive &= (pivot > 0) & (pivot < np.inf)
            factor = reduced[:, k + 1 :, k] / np.where(positive, pivot, 1.0)[:, None]
            reduced[:, k + 1 :, k + 1 :] -= factor[:, :, None] * reduced[:, k, k + 1 :][:, None, :]
    return positive


def definite_beyond(matrices: np.ndarray, share: float) -> np.ndarray:
    """Whether each of (n, d, d) symmetric matrices stays positive definite less ``share`` of
    its trace on its diagonal: then every eigenvalue exceeds ``share`` λ_max (λ_max ≤ trace)."""
    trace = np.trace(matrices, axis1=1, axis2=2)
    return positive_definite(matrices - share * trace[:, None, None] * np.eye(matrices.shape[-1]))


def information_problems(information: np.ndarray) -> tuple[np.ndarray, Callable[[int], str]]:
    """Which of (n, d, d) information matrices are refused, and why the k-th is: not finite,
    not symmetric (|Ω − Ωᵀ| > 1e-9 max|Ω|), zero, or not positive semi-definite
    (λ_min < −1e-9 max|Ω|). A zero eigenvalue is a direction not measured, as in a
    position-only prior, and is allowed."""
    with np.errstate(invalid="ignore"):
        size = np.abs(information).max(axis=(1, 2))  # NaN or ∞ where an entry is
        asymmetry = np.abs(information - np.swapaxes(information, 1, 2)).max(axis=(1, 2))
    symmetric = np.isfinite(size) & (asymmetry <= 1e-9 * size)
    smallest = np.full(len(information), np.nan)  # fails every comparison where not symmetric
    smallest[symmetric] = np.inf  # λ_min > 0 where definite; the others' is computed
    semi = np.flatnonzero(symmetric)[~positive_definite(information[symmetric])]
    smallest[semi] = np.linalg.eigvalsh(information[semi])[:, 0]
    bad = ~(smallest >= -1e-9 * size) | (size == 0)

    def why(k: int) -> str:
        if not np.isfinite(size[k]):
            return "not finite"
        if not symmetric[k]:
            return "not symmetric"
        if size[k] == 0:
            return "zero (it would weigh nothing)"
        return f"not positive semi-definite (λ_min = {smallest[k]:.3g})"

    return bad, why


def start_information(measurements: LieGroup, information: np.ndarray) -> np.ndarray:
    """Each between edge's information on its start node's tangent where its residual is zero,
    Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹): there ∂r/∂δᵢ = −Ad(Z⁻¹) (CONVENTIONS.md)."""
    adjoint = measurements.inverse().adjoint()
    return np.swapaxes(adjoint, 1, 2) @ information @ adjoint


def overflowing_edges(measurements: LieGroup, information: np.ndarray) -> np.ndarray:
    """Which between edges' ``start_information`` overflows: their translation, weighed by
    their information, is too large for double precision (beyond about 1e154 for a unit
    information), so no cost or normal equations can hold them."""
    with np.errstate(over="ignore", invalid="ignore"):
        return ~np.isfinite(start_information(measurements, information)).all(axis=(1, 2))


def refuse_overflowing(new, kind: str, node_id: Callable[[int], int]) -> None:
    """Refuse measurements (an ``EdgeSet`` of ``kind`` "edge" or "prior"; ``node_id`` names a
    node by its index) whose translation weighed by their information overflows
    (``overflowing_edges``)."""
    overflowing = np.flatnonzero(overflowing_edges(new.measurements, new.information))
    if overflowing.size:
        i, j = node_id(new.i[overflowing[0]]), node_id(new.j[overflowing[0]])
        which = f"the edge {i} → {j}" if kind == "edge" else f"the prior on node {i}"
        raise ValueError(
            f"{which}: its translation weighed by its information overflows "
            f"(Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) at node {i}); it is too large for double precision"
        )


def information_ranks(information: np.ndarray) -> np.ndarray:
    """rank Ωₖ of each of (n, d, d) information matrices: the directions it weighs (2 for an
    SE2 position-only prior, not 3), counting eigenvalues above the tolerance of
    ``information_problems``."""
    if not len(information):
        return np.zeros(0, dtype=int)
    count, d = information.shape[:2]
    ranks = np.full(count, d)
    rest = np.flatnonzero(~definite_beyond(information, 1e-9))  # the others have rank d
    eigenvalues = np.linalg.eigvalsh(information[rest])
    ranks[rest] = np.count_nonzero(eigenvalues > 1e-9 * eigenvalues[:, -1:], axis=1)
    return ranks


def measured_dof(information: np.ndarray) -> int:
    """Σ rank Ωₖ over (n, d, d) information matrices (``information_ranks``)."""
    return int(information_ranks(information).sum())


def as_elements(
    group: type[LieGroup], values, count: int, describe: Callable[[int], str]
) -> LieGroup:
    """``count`` elements of the group from elements or (…, n, n) matrices (one is
    broadcast). Either is refused if it is not finite, if its linear block has determinant
    ≤ 0 (a Sim3 of scale 0, say), or if it is off the group by more than 1e-4 (relative to its
    linear block). Matrices are normalised: rounding drift is projected away; elements are
    kept as they are. A refusal is a ``ValueError`` naming ``describe(k)`` for the k-th."""
    n = group.matrix_size
    element = isinstance(values, LieGroup)
    if element:
        if not isinstance(values, group):
            raise TypeError(f"values are {type(values).__name__}, the graph is {group.__name__}")
        if values.batch_shape not in ((), (count,)):
            stacked = f" (or {count})" if count > 1 else ""
            raise ValueError(
                f"{group.__name__} elements are one{stacked}, not of batch shape "
                f"{values.batch_shape}"
            )
        values = values if values.batch_shape == (count,) else values.broadcast_to((count,))
        given = values.as_matrix()
    else:
        given = np.asarray(values, float)
        if given.shape not in ((n, n), (count, n, n)):
            stacked = f" (or {count} × {n} × {n})" if count > 1 else ""
            raise ValueError(
                f"{group.__name__} matrices are {n} × {n}{stacked}, not of shape {given.shape}"
            )
        given = np.broadcast_to(given, (count, n, n))
    finite = np.isfinite(given).all(axis=(1, 2))
    if not finite.all():
        raise ValueError(f"{describe(int(np.flatnonzero(~finite)[0]))} is not finite")
    degenerate, why = element_problems(given)
    if degenerate.any():  # refused before the projection, which needs det > 0
        k = int(np.flatnonzero(degenerate)[0])
        raise ValueError(
            f"{describe(k)} is not an element of {group.__name__} (its matrix has {why(k)})"
        )
    linear = given[:, :-1, :-1]
    normalized = group.from_matrix(given).normalize()
    off = np.abs(normalized.as_matrix() - given).max(axis=(1, 2))
    bad = np.flatnonzero(off > 1e-4 * np.maximum(np.abs(linear).max(axis=(1, 2)), 1))
    if bad.size:
        k = int(bad[0])
        raise ValueError(
            f"{describe(k)} is not an element of {group.__name__} (its matrix is off the "
            f"group by {off[k]:.3g})"
        )
    return values if element else normalized


def as_information(
    group: type[LieGroup], information, count: int, describe: Callable[[int], str]
) -> np.ndarray:
    """(count, d, d) information from one (d, d) or (count, d, d), each passing
    ``information_problems``; else ``ValueError`` names ``describe(k)`` for the k-th."""
    d = group.dof
    information = np.asarray(information, float)
    if information.shape not in ((d, d), (count, d, d)):
        stacked = f" (or {count} × {d} × {d} for {count} measurements)" if count > 1 else ""
        raise ValueError(
            f"information must be {d} × {d} for {group.__name__}{stacked}, "
            f"not of shape {information.shape}"
        )
    information = np.broadcast_to(information, (count, d, d)).copy()
    bad, why = information_problems(information)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{describe(k)} is {why(k)}")
    return information
