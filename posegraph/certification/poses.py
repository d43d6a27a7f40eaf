"""The preconditioner of the trust region at rank d, where Y = R holds rotations: Newton's
system of SE-Sync's cost Σₑ κₑ ‖Rⱼ − Rᵢ R̃ₑ‖²_F + τₑ ‖tⱼ − tᵢ − Rᵢ t̃ₑ‖² over poses, perturbed
as Rᵢ exp(kᵢ^) and tᵢ + δtᵢ, pose 0 held. Its Gauss-Newton part Jᵀ W J is a pose graph's
normal equations (sparse: ``problem.linear.BlockPattern``), whose Schur complement on the
rotations is Bᵀ Q B, with B kᵢ = Rᵢ kᵢ^ the tangent vectors; the second-order term of
exp(kᵢ^) adds tr(G_a G_b Λᵢ) to pose i's rotation block. Together they are half the Riemannian
Hessian Bᵀ Hess F B (SE-Sync eq. 44), so conjugate gradients take a step or two, where Q
alone (SE-Sync §4.1.2), which lacks Λ, needed tens near the minimum."""

from __future__ import annotations

import numpy as np

from ..lie._coeffs import hat3
from ..problem.cholesky import NotPositiveDefinite
from ..problem.linear import BlockPattern
from ..problem.pattern import free_block_index
from .data import SESyncData
from .stiefel import blocks, joined


def generators(d: int) -> np.ndarray:
    """A basis of the skew-symmetric d × d matrices (p, d, d), p = d(d − 1)/2."""
    if d == 2:
        return np.array([[[0.0, -1.0], [1.0, 0.0]]])
    return hat3(np.eye(3))


class PosePreconditioner:
    """V ↦ B H⁻¹ Bᵀ V at the rotations of the last ``factorize``, H the pose system's Schur
    complement on the rotations: its pattern analysed once, factorised at each Y, solved with
    zero load on the translations."""

    def __init__(self, data: SESyncData) -> None:
        d = self.d = data.d
        self.data = data
        self.skew = generators(d)
        self.dof = d + self.skew.shape[0]
        every = np.arange(data.n)  # a unary block per pose: the second-order term
        held = free_block_index(data.n, np.zeros(1, dtype=np.int64))  # pose 0
        self.pattern = BlockPattern(held, data.edge_i, data.edge_j, every, self.dof)
        weights = [np.repeat(data.kappa[:, None], d * d, 1), np.repeat(data.tau[:, None], d, 1)]
        self.weights = np.concatenate(weights, axis=1)[:, :, None]
        self.tangents = np.zeros((data.n, self.dof - d, d, d))

    def factorize(self, y: np.ndarray, multipliers: np.ndarray) -> None:
        """The Hessian at the rotations ``y`` (d × dn) with Λ's blocks ``multipliers``, or
        where it is not positive definite (far from a minimum), its Gauss-Newton part,
        factorised."""
        d = self.d
        self.tangents = blocks(y, d)[:, None] @ self.skew  # (n, p, d, d): Rᵢ G_a
        jacobians = self._jacobians()
        normal = np.swapaxes(jacobians, 1, 2) @ (jacobians * self.weights)
        second = np.zeros((self.data.n, self.dof, self.dof))
        products = self.skew[:, None] @ self.skew[None]  # G_a G_b
        second[:, d:, d:] = np.einsum("abij,nji->nab", products, multipliers)  # tr(G_a G_b Λᵢ)

        def matrix(unary: np.ndarray) -> np.ndarray:
            return self.pattern.matrix_data(np.concatenate([normal.ravel(), unary.ravel()]))

        try:
            self.pattern.factorize(matrix(second))
        except NotPositiveDefinite:
            self.pattern.factorize_regularized(matrix(np.zeros_like(second)))

    def _jacobians(self) -> np.ndarray:
        """Each edge's Jacobian (m, d² + d, 2 dof) of (vec(Rⱼ − Rᵢ R̃), tⱼ − tᵢ − Rᵢ t̃) in
        (δtᵢ, kᵢ, δtⱼ, kⱼ)."""
        data = self.data
        i, j, rotation, translation = (
            data.edge_i,
            data.edge_j,
            data.edge_rotations,
            data.edge_translations,
        )
        d, dof, m = self.d, self.dof, i.size
        jacobian = np.zeros((m, d * d + d, 2 * dof))
        at_i, at_j = self.tangents[i], self.tangents[j]  # (m, p, d, d)
        jacobian[:, : d * d, d:dof] = (
            -(at_i @ rotation[:, None]).reshape(m, -1, d * d).swapaxes(1, 2)
        )
        jacobian[:, : d * d, dof + d :] = at_j.reshape(m, -1, d * d).swapaxes(1, 2)
        jacobian[:, d * d :, :d] = -np.eye(d)
        jacobian[:, d * d :, dof : dof + d] = np.eye(d)
        jacobian[:, d * d :, d:dof] = -(at_i @ translation[:, None, :, None])[..., 0].swapaxes(1, 2)
        return jacobian

    def residual_norm(self, v: np.ndarray) -> float:
        """‖V‖ without pose 0's block: the preconditioner holds pose 0's rotation (the gauge),
        so conjugate gradients solve Newton's system over the other poses, and this is the
        norm of its residual (at rank d a tangent's block is Rᵢ kᵢ^, all of it rotation)."""
        return float(np.linalg.norm(v[:, self.d :]))

    def __call__(self, v: np.ndarray) -> np.ndarray:
        d, dof = self.d, self.dof
        load = np.zeros((self.data.n, dof))
        load[:, d:] = np.einsum("npab,nab->np", self.tangents, blocks(v, d))  # Bᵀ V
        free = self.pattern.block_of >= 0
        solved = self.pattern.scatter(self.pattern.solve(load[free].ravel()))  # (n, dof)
        return joined(np.einsum("np,npab->nab", solved[:, d:], self.tangents))
