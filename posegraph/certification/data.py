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
import functools
from typing import TYPE_CHECKING

import numpy as np

from ..graph import PoseGraph
from ..lie import SE2, SE3
from ..problem.backends import make_cholesky
from ..problem.cholesky import NotPositiveDefinite

if TYPE_CHECKING:
    import scipy.sparse


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
    scale: float
    """The largest diagonal entry of L(G̃ρ) + T Ω Tᵀ: the size of Q's entries."""
    joint: scipy.sparse.csc_matrix
    """The sparse matrix of the cost in the reduced translations and the rotations,
    [[Ā Ω Āᵀ, Ā Ω Tᵀ], [T Ω Āᵀ, L(G̃ρ) + T Ω Tᵀ]], of which Q is the Schur complement."""
    edge_i: np.ndarray
    """Each edge's first node (m,)."""
    edge_j: np.ndarray
    """Each edge's second node (m,)."""
    kappa: np.ndarray
    """κₑ (m,)."""
    edge_rotations: np.ndarray
    """R̃ₑ (m, d, d)."""
    edge_translations: np.ndarray
    """t̃ₑ (m, d)."""

    @functools.cached_property
    def preconditioner(self) -> object:
        """The Cholesky factor of ``joint`` + εI on the rotations (ε: 1e-6 of the largest
        diagonal entry, as Q can be singular along the global rotation): it applies (Q + εI)⁻¹,
        SE-Sync's regularised Cholesky preconditioner. Factorised on first use: above rank d
        and for a failed check."""
        import scipy.sparse  # on use: commands that do not certify do without scipy

        shift = np.r_[np.zeros(self.n - 1), np.full(self.d * self.n, 1e-6 * self.scale)]
        return _factorized(self.joint + scipy.sparse.diags(shift))

    def precondition(self, y: np.ndarray) -> np.ndarray:
        """Y (Q + εI)⁻¹ for Y of shape (k, dn): the rotation block of the solution of the
        regularised ``joint`` system with zero translation load, Q + εI being its Schur
        complement on the rotations."""
        load = np.zeros((self.n - 1 + y.shape[1], y.shape[0]))
        load[self.n - 1 :] = y.T
        return self.preconditioner.solve(load)[self.n - 1 :].T

    def factor_less(self, blocks: np.ndarray, shift: float):
        """The Cholesky factor of ``joint`` less the block-diagonal B (``blocks``, (n, d, d))
        plus δI (δ = ``shift``) on the rotations, whose Schur complement on them is
        Q − B + δI; None where that matrix is not positive definite."""
        import scipy.sparse

        d, n = self.d, self.n
        entries = n - 1 + np.arange(d * n).reshape(n, d)
        rows = np.broadcast_to(entries[:, :, None], (n, d, d)).ravel()
        cols = np.broadcast_to(entries[:, None, :], (n, d, d)).ravel()
        change = (shift * np.eye(d) - blocks).ravel()
        correction = scipy.sparse.coo_matrix((change, (rows, cols)), shape=self.joint.shape)
        try:
            return _factorized(self.joint + correction)
        except NotPositiveDefinite:
            return None

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


def require_certifiable(graph: PoseGraph) -> None:
    """Refuse, naming why, a graph that SE-Sync's problem cannot hold: not SE2 or SE3, with
    priors, not connected, or with a translation or rotation information block that is not
    positive definite (its isotropic precision would be 0 or undefined)."""
    if graph.group not in (SE2, SE3):
        raise ValueError(f"certification is for SE2 and SE3 graphs, not {graph.group.__name__}")
    if len(graph.priors):
        raise ValueError("SE-Sync's problem has no priors: certify a graph without them")
    if graph.num_nodes < 2 or graph.components().max() > 0:
        raise ValueError("certification needs a connected graph of two poses or more")
    d = 2 if graph.group is SE2 else 3
    information = graph.edges.information
    for name, block in (
        ("translation", information[:, :d, :d]),
        ("rotation", information[:, d:, d:]),
    ):
        definite = np.linalg.eigvalsh(0.5 * (block + np.swapaxes(block, 1, 2)))[:, 0] > 0
        if not definite.all():
            e = int(np.flatnonzero(~definite)[0])
            ids = graph.node_ids[[graph.edges.i[e], graph.edges.j[e]]]
            raise ValueError(
                f"edge {ids[0]} → {ids[1]}: its {name} information is not positive definite "
                "(SE-Sync's isotropic model needs a precision in every direction; "
                "--repair-information isotropic makes one)"
            )


def sesync_data(graph: PoseGraph) -> SESyncData:
    """SE-Sync's problem of an SE2 or SE3 graph without priors, its edges' information reduced
    to κ and τ (``precisions``). The graph must be connected."""
    import scipy.sparse

    require_certifiable(graph)
    group = graph.group
    d, n, edges = (2 if group is SE2 else 3), graph.num_nodes, graph.edges
    m = len(edges)
    kappa, tau = precisions(group, edges.information)
    measured = edges.measurements.as_matrix()
    rotation, translation = measured[:, :d, :d], measured[:, :d, d]
    i, j = edges.i, edges.j
    block = np.arange(d)
    laplacian = _connection_laplacian(i, j, kappa, rotation, n)
    translations = scipy.sparse.coo_matrix(
        (-translation.ravel(), ((i[:, None] * d + block).ravel(), np.repeat(np.arange(m), d))),
        shape=(d * n, m),
    ).tocsr()
    incidence = scipy.sparse.coo_matrix(
        (np.r_[-np.ones(m), np.ones(m)], (np.r_[i, j], np.r_[np.arange(m), np.arange(m)])),
        shape=(n, m),
    ).tocsr()[1:]
    reduced = incidence @ scipy.sparse.diags(tau) @ incidence.T
    rotational = laplacian + translations @ scipy.sparse.diags(tau) @ translations.T
    coupling = incidence @ scipy.sparse.diags(tau) @ translations.T
    joint = scipy.sparse.bmat([[reduced, coupling], [coupling.T, rotational]]).tocsc()
    scale = float(rotational.diagonal().max())
    return SESyncData(
        d,
        n,
        laplacian,
        translations,
        incidence,
        tau,
        _factorized(reduced),
        scale,
        joint,
        i,
        j,
        kappa,
        rotation,
        translation,
    )


def _connection_laplacian(i, j, kappa: np.ndarray, rotation: np.ndarray, n: int):
    """L(G̃ρ), dn × dn: κ I on the diagonal blocks of both ends of each edge, −κ R̃ at (i, j)
    and −κ R̃ᵀ at (j, i) (SE-Sync eq. 13)."""
    import scipy.sparse

    m, d = rotation.shape[0], rotation.shape[-1]
    block = np.arange(d)
    at_i, at_j = i[:, None, None] * d, j[:, None, None] * d
    rows = [
        at_i + block[:, None],
        at_j + block[:, None],
        at_i + block[:, None],
        at_j + block[:, None],
    ]
    cols = [at_i + block, at_j + block, at_j + block, at_i + block]
    weight = kappa[:, None, None]
    values = [weight * np.eye(d), weight * np.eye(d), -weight * rotation,
              -weight * np.swapaxes(rotation, 1, 2)]  # fmt: skip
    shape = (m, d, d)
    return scipy.sparse.coo_matrix(
        (
            np.concatenate([np.broadcast_to(v, shape).ravel() for v in values]),
            (
                np.concatenate([np.broadcast_to(r, shape).ravel() for r in rows]),
                np.concatenate([np.broadcast_to(c, shape).ravel() for c in cols]),
            ),
        ),
        shape=(d * n, d * n),
    ).tocsr()


def _factorized(matrix) -> object:
    """A Cholesky factor (``problem.cholesky``) of a sparse positive definite matrix."""
    import scipy.sparse

    matrix = scipy.sparse.csc_matrix(matrix)
    matrix.sort_indices()
    factor = make_cholesky(matrix.indices, matrix.indptr, matrix.shape[0])
    factor.factorize(matrix.data)
    return factor
