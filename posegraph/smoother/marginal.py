"""Quadratic models of a window's measurements over the tangents of its nodes, and the Gaussian
prior that marginalising some of those nodes leaves on the others (Schur complement; Sibley,
Matthies and Sukhatme 2010, "Sliding window filter", §3)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..graph import EdgeSet
from ..lie import LieGroup
from ..problem.factors import linearize_between, linearize_priors
from .band import BandMatrix

if TYPE_CHECKING:
    import scipy.sparse

DENSE_SIZE = 1500
"""Systems whose band is half their size or wider are held and solved dense up to this many
unknowns, sparse beyond; narrower bands as band matrices (``storage``)."""


@dataclasses.dataclass(frozen=True)
class GaussianPrior:
    """½ δᵀ H δ − gᵀ δ + c over the stacked tangents δ of ``nodes`` (graph indices) at their
    linearisation points: what marginalisation leaves of the measurements it removed."""

    nodes: np.ndarray
    hessian: np.ndarray
    gradient: np.ndarray
    constant: float

    def error(self, delta: np.ndarray) -> float:
        """The prior's error at the nodes' tangents ``delta`` (len(nodes), d)."""
        flat = delta.reshape(-1)
        return float(0.5 * flat @ self.hessian @ flat - self.gradient @ flat + self.constant)


@dataclasses.dataclass(frozen=True)
class Quadratic:
    """½ δᵀ H δ − gᵀ δ + c over the stacked tangents of n nodes (H n·d square): the
    first-order model of measurements, ½ Σ ‖r + J δ‖²_Ω, around their linearisation point.
    H is zero more than ``bandwidth`` entries off its diagonal, and held as ``storage`` says."""

    hessian: np.ndarray | BandMatrix | scipy.sparse.csr_matrix
    gradient: np.ndarray
    constant: float
    bandwidth: int

    @property
    def storage(self) -> str:
        """How H is held: "band", "dense" or "scipy" (sparse)."""
        if isinstance(self.hessian, BandMatrix):
            return "band"
        return "dense" if isinstance(self.hessian, np.ndarray) else "scipy"

    def decrease(self, start: np.ndarray, end: np.ndarray) -> float:
        """How much the model falls from tangents ``start`` to ``end`` (stacked)."""
        step = end - start
        return float(
            self.gradient @ step
            - 0.5 * (end @ (self.hessian @ end) - start @ (self.hessian @ start))
        )


def quadratic(
    values: LieGroup,
    edges: EdgeSet,
    priors: EdgeSet,
    position: np.ndarray,
    prior: GaussianPrior | None = None,
) -> Quadratic:
    """The ``Quadratic`` of between ``edges`` and unary ``priors`` linearised at ``values`` (every
    node's), plus a ``GaussianPrior``, over the nodes whose ``position`` (per node) is ≥ 0, in
    that order; the others are constants. H is held as ``storage`` chooses."""
    d, n = values.dof, int(position.max(initial=-1)) + 1
    between, unary = linearize_between(values, edges), linearize_priors(values, priors)
    parts = [
        _blocks(between.residuals, between.jac_i, between.jac_j, edges, position),
        _blocks(unary.residuals, unary.jac_j, None, priors, position),
    ]
    rows, cols, blocks, nodes, pieces = (np.concatenate([p[k] for p in parts]) for k in range(5))
    gradient = np.zeros((n, d))
    np.add.at(gradient, nodes, pieces)
    gradient = gradient.reshape(-1)
    constant = parts[0][5] + parts[1][5]
    reach = np.abs(rows - cols).max(initial=0)
    if prior is not None:
        reach = max(reach, np.ptp(position[prior.nodes]))
    bandwidth = int(reach + 1) * d - 1
    hessian = _assembled(rows, cols, blocks, n, bandwidth)
    if prior is not None:
        at = (position[prior.nodes][:, None] * d + np.arange(d)).reshape(-1)
        if isinstance(hessian, BandMatrix):
            hessian.add(at, prior.hessian)
        elif isinstance(hessian, np.ndarray):
            hessian[np.ix_(at, at)] += prior.hessian
        else:
            hessian = hessian + _embedded(prior.hessian, at, n * d)
        gradient[at] += prior.gradient
        constant += prior.constant
    return Quadratic(hessian, gradient, float(constant), bandwidth)


def storage(size: int, bandwidth: int) -> str:
    """How a window's H of ``size`` unknowns and ``bandwidth`` is held: as a band matrix where
    its band is narrower than half its size, else dense up to ``DENSE_SIZE`` unknowns, else
    sparse (scipy)."""
    if 2 * bandwidth < size:
        return "band"
    return "dense" if size <= DENSE_SIZE else "scipy"


def _assembled(rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray, n: int, bandwidth: int):
    """The n·d square matrix of (d, d) ``blocks`` summed at block ``rows`` and ``cols``, held as
    ``storage`` chooses for its ``bandwidth``."""
    d = blocks.shape[-1]
    size = n * d
    held = storage(size, bandwidth)
    if held == "band":
        return BandMatrix.of_blocks(rows, cols, blocks, size, bandwidth)
    entry_rows = (rows[:, None, None] * d + np.arange(d)[:, None]).repeat(d, axis=2)
    entry_cols = (cols[:, None, None] * d + np.arange(d)[None, :]).repeat(d, axis=1)
    if held == "dense":
        flat = (entry_rows * size + entry_cols).ravel()
        return np.bincount(flat, blocks.ravel(), size**2).reshape(size, size)
    import scipy.sparse  # on use: dense windows do without it

    return scipy.sparse.coo_matrix(
        (blocks.ravel(), (entry_rows.ravel(), entry_cols.ravel())), shape=(n * d, n * d)
    ).tocsr()


def _blocks(residuals, jac_i, jac_j, edges: EdgeSet, position: np.ndarray):
    """(block rows, block columns, JₐᵀΩJ_b blocks, gradient nodes, −JₐᵀΩr pieces, ½ΣrᵀΩr) of
    edges (between if ``jac_j`` is given, else unary on ``edges.i``), over free nodes only."""
    information = edges.information
    weighted = np.einsum("mij,mj->mi", information, residuals)
    count, d = residuals.shape
    if jac_j is None:
        ends, jacobians = edges.i[:, None], jac_i
    else:
        ends, jacobians = np.stack([edges.i, edges.j], axis=1), np.concatenate([jac_i, jac_j], 2)
    k = ends.shape[1]
    hessians = np.swapaxes(jacobians, 1, 2) @ information @ jacobians  # (m, k·d, k·d)
    blocks = hessians.reshape(count, k, d, k, d).transpose(0, 1, 3, 2, 4)  # (m, a, b, d, d)
    pieces = -np.einsum("mji,mj->mi", jacobians, weighted).reshape(count, k, d)
    at = position[ends]  # (m, k)
    rows = np.broadcast_to(at[:, :, None], (count, k, k))
    cols = np.broadcast_to(at[:, None, :], (count, k, k))
    free = (rows >= 0) & (cols >= 0)
    constant = 0.5 * float(np.einsum("mi,mi->", residuals, weighted))
    return rows[free], cols[free], blocks[free], at[at >= 0], pieces[at >= 0], constant


def _embedded(matrix: np.ndarray, at: np.ndarray, size: int) -> scipy.sparse.csr_matrix:
    """A dense square ``matrix`` placed at rows and columns ``at`` of a size × size matrix."""
    import scipy.sparse

    rows = np.repeat(at, at.size)
    cols = np.tile(at, at.size)
    return scipy.sparse.coo_matrix((matrix.ravel(), (rows, cols)), shape=(size, size)).tocsr()


def marginalized(
    model: Quadratic, kept: np.ndarray, d: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """(H, g, c) of ``model`` minimised over the nodes not ``kept`` (a mask over its nodes), on
    the kept ones: the Schur complement H_kk − H_km H_mm⁺ H_mk, g_k − H_km H_mm⁺ g_m and
    c − ½ g_mᵀ H_mm⁺ g_m (pseudo-inverse: a direction that nothing measures stays unmeasured)."""
    entries = np.repeat(kept, d)
    dense = model.hessian
    if not isinstance(dense, np.ndarray):
        dense = dense.toarray()  # a band or sparse H
    h_kk = dense[np.ix_(entries, entries)]
    h_km = dense[np.ix_(entries, ~entries)]
    h_mm = dense[np.ix_(~entries, ~entries)]
    g_k, g_m = model.gradient[entries], model.gradient[~entries]
    inverse = np.linalg.pinv(h_mm, hermitian=True)
    hessian = h_kk - h_km @ inverse @ h_km.T
    return (
        0.5 * (hessian + hessian.T),
        g_k - h_km @ inverse @ g_m,
        model.constant - 0.5 * float(g_m @ inverse @ g_m),
    )
