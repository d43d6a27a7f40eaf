"""SE-Sync's problem for an SE2 or SE3 pose graph (Rosen, Carlone, Bandeira and Leonard, IJRR
2019, §3–4): each edge's isotropic precisions κ (rotation) and τ (translation), and the data
matrix Q of the rotation-only problem left once the translations are eliminated,

    minimise F(R) = tr(R Q Rᵀ) over R = [R₁ … Rₙ] ∈ SO(d)ⁿ,   Q = L(G̃ρ) + T Ω^½ Π Ω^½ Tᵀ,

the cost Σₑ κₑ ‖Rⱼ − Rᵢ R̃ₑ‖²_F + τₑ ‖tⱼ − tᵢ − Rᵢ t̃ₑ‖² at its best translations (eq. 20).
Q is applied as an operator: the connection Laplacian L(G̃ρ) and T are sparse, and Π, the
projection off the incidence matrix's row space, is a solve with the reduced translational
Laplacian, factorised once (``problem.cholesky``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse

from ..graph import PoseGraph
from ..lie import SE2, SE3
from ..problem.cholesky import make_cholesky


def precisions(group: type, information: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(κ, τ) of each edge from its (d, d) information over (translation, rotation), as SE-Sync
    reads a g2o file: τ = d / tr(Ω_tt⁻¹); κ = Ω_θθ in 2D, 3 / (2 tr(Ω_φφ⁻¹)) in 3D."""
    d = 2 if group is SE2 else 3
    translation = np.linalg.inv(information[:, :d, :d])
    tau = d / np.trace(translation, axis1=1, axis2=2)
    if group is SE2:
        return information[:, 2, 2].copy(), tau
    rotation = np.linalg.inv(information[:, d:, d:])
    return 3.0 / (2.0 * np.trace(rotation, axis1=1, axis2=2)), tau


@dataclasses.dataclass
class SESyncData:
    """Q as an operator on r × dn matrices Y (``product``: Y ↦ Y Q), with what recovers the
    translations. Pose 0's translation is held at zero (the gauge)."""

    d: int
    n: int
    connection_laplacian: scipy.sparse.csr_matrix
    """L(G̃ρ), dn × dn."""
    translations: scipy.sparse.csr_matrix
    """T, dn × m: block i of column e is −t̃ₑ for the edge e = (i, j)."""
    incidence: scipy.sparse.csr_matrix
    """Ā, (n − 1) × m: the oriented incidence matrix without pose 0's row."""
    tau: np.ndarray
    laplacian_factor: object
    """The Cholesky factor of Ā Ω Āᵀ, Ω = diag(τ)."""
    preconditioner: object
    """The Cholesky factor of L(G̃ρ) + T Ω Tᵀ + εI, a sparse matrix above Q (Q is it less a
    positive semidefinite term; T Ω Tᵀ is block diagonal), whose inverse preconditions."""
    scale: float
    """The largest diagonal entry of L(G̃ρ) + T Ω Tᵀ: the size of Q's entries."""

    def precondition(self, y: np.ndarray) -> np.ndarray:
        """Y M⁻¹ for Y of shape (k, dn), M the ``preconditioner``'s matrix."""
        return self.preconditioner.solve(np.ascontiguousarray(y.T)).T

    def product(self, y: np.ndarray) -> np.ndarray:
        """Y Q for Y of shape (k, dn)."""
        weighted = (self.translations.T @ y.T).T * self.tau
        solved = self.laplacian_factor.solve(np.ascontiguousarray(self.incidence @ weighted.T))
        projected = weighted - (self.incidence.T @ solved).T * self.tau
        return (self.connection_laplacian @ y.T).T + (self.translations @ projected.T).T

    def objective(self, y: np.ndarray) -> float:
        """F(Y) = tr(Y Q Yᵀ)."""
        return float(np.sum(y * self.product(y)))

    def recover_translations(self, rotations: np.ndarray) -> np.ndarray:
        """The translations (n, d) that minimise the cost with ``rotations`` (d × dn) held,
        pose 0's at the origin (SE-Sync eq. 21)."""
        weighted = (self.translations.T @ rotations.T).T * self.tau
        rest = -self.laplacian_factor.solve(np.ascontiguousarray(self.incidence @ weighted.T))
        return np.vstack([np.zeros((1, self.d)), rest])


def sesync_data(graph: PoseGraph) -> SESyncData:
    """SE-Sync's problem of an SE2 or SE3 graph without priors, its edges' information reduced
    to κ and τ (``precisions``). The graph must be connected."""
    group = graph.group
    if group not in (SE2, SE3):
        raise ValueError(f"certification is for SE2 and SE3 graphs, not {group.__name__}")
    if len(graph.priors):
        raise ValueError("SE-Sync's problem has no priors: certify a graph without them")
    if graph.num_nodes and graph.components().max() > 0:
        raise ValueError("certification needs a connected graph")
    d, n, edges = (2 if group is SE2 else 3), graph.num_nodes, graph.edges
    m = len(edges)
    kappa, tau = precisions(group, edges.information)
    measured = edges.measurements.as_matrix()
    rotation, translation = measured[:, :d, :d], measured[:, :d, d]
    i, j = edges.i, edges.j
    block = np.arange(d)
    eye = np.broadcast_to(np.eye(d), (m, d, d)) * kappa[:, None, None]
    rows = [i[:, None, None] * d + block[:, None], j[:, None, None] * d + block[:, None]]
    cols = [i[:, None, None] * d + block[None, :], j[:, None, None] * d + block[None, :]]
    entries = [
        (rows[0], cols[0], eye),
        (rows[1], cols[1], eye),
        (rows[0], cols[1], -kappa[:, None, None] * rotation),
        (rows[1], cols[0], -kappa[:, None, None] * np.swapaxes(rotation, 1, 2)),
    ]
    laplacian = scipy.sparse.coo_matrix(
        (
            np.concatenate([np.broadcast_to(v, (m, d, d)).ravel() for _, _, v in entries]),
            (
                np.concatenate([np.broadcast_to(r, (m, d, d)).ravel() for r, _, _ in entries]),
                np.concatenate([np.broadcast_to(c, (m, d, d)).ravel() for _, c, _ in entries]),
            ),
        ),
        shape=(d * n, d * n),
    ).tocsr()
    translations = scipy.sparse.coo_matrix(
        (-translation.ravel(), ((i[:, None] * d + block).ravel(), np.repeat(np.arange(m), d))),
        shape=(d * n, m),
    ).tocsr()
    incidence = scipy.sparse.coo_matrix(
        (np.r_[-np.ones(m), np.ones(m)], (np.r_[i, j], np.r_[np.arange(m), np.arange(m)])),
        shape=(n, m),
    ).tocsr()[1:]
    reduced = incidence @ scipy.sparse.diags(tau) @ incidence.T
    bound = _upper_bound(laplacian, translations, tau)
    return SESyncData(
        d,
        n,
        laplacian,
        translations,
        incidence,
        tau,
        _factorized(reduced),
        _factorized(bound),
        float(bound.diagonal().max()),
    )


def _upper_bound(laplacian, translations, tau: np.ndarray) -> scipy.sparse.csc_matrix:
    """L(G̃ρ) + T Ω Tᵀ, regularised by 1e-6 of its largest diagonal entry (L(G̃ρ) is singular
    along the global rotation)."""
    bound = (laplacian + translations @ scipy.sparse.diags(tau) @ translations.T).tocsc()
    return bound + scipy.sparse.identity(bound.shape[0]) * 1e-6 * bound.diagonal().max()


def _factorized(matrix) -> object:
    """A Cholesky factor (``problem.cholesky``) of a sparse positive definite matrix."""
    matrix = scipy.sparse.csc_matrix(matrix)
    matrix.sort_indices()
    factor = make_cholesky(matrix.indices, matrix.indptr, matrix.shape[0])
    factor.factorize(matrix.data)
    return factor
