"""Batched residuals, analytic Jacobians and cost of between edges and priors.

CONVENTIONS.md (binding):

* between i → j with measurement Z: ``r = Log(Z⁻¹ Xᵢ⁻¹ Xⱼ)``,
  ``∂r/∂δⱼ = jr⁻¹(r)`` and ``∂r/∂δᵢ = −jr⁻¹(r) Ad(Xⱼ⁻¹ Xᵢ)``;
* prior on X with measurement Z: ``r = Log(Z⁻¹ X)``, ``∂r/∂δ = jr⁻¹(r)``;
* ``error = ½ Σ rᵀ Ω r`` (gtsam's ``graph.error``) and ``chi2 = Σ rᵀ Ω r`` (what g2o prints).

One implementation serves SE2, SE3 and Sim3 through the group API.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import EdgeSet
from ..lie import LieGroup


@dataclasses.dataclass(frozen=True)
class Linearization:
    """Residuals (m, d) and Jacobians of every edge: (m, d, 2d) [∂r/∂δᵢ ∂r/∂δⱼ] of between
    edges, (m, d, d) ∂r/∂δ of priors."""

    residuals: np.ndarray
    jacobians: np.ndarray

    @property
    def jac_i(self) -> np.ndarray:
        """∂r/∂δᵢ (m, d, d) of between edges."""
        return self.jacobians[..., : self.residuals.shape[-1]]

    @property
    def jac_j(self) -> np.ndarray:
        """∂r/∂δⱼ (m, d, d) of between edges, ∂r/∂δ of priors."""
        return self.jacobians[..., -self.residuals.shape[-1] :]

    def extended(self, other: Linearization) -> Linearization:
        """This linearisation followed by ``other``'s edges."""
        return Linearization(
            np.concatenate([self.residuals, other.residuals]),
            np.concatenate([self.jacobians, other.jacobians]),
        )


def relative_poses(values: LieGroup, edges: EdgeSet) -> LieGroup:
    """Xᵢ⁻¹ Xⱼ of every between edge."""
    return values[edges.i].between(values[edges.j])


def residuals_of(relative: LieGroup, edges: EdgeSet) -> np.ndarray:
    """r = Log(Z⁻¹ Xᵢ⁻¹ Xⱼ) of every between edge, from its relative pose Xᵢ⁻¹ Xⱼ."""
    return edges.measurements.between(relative).log()


def between_residuals(values: LieGroup, edges: EdgeSet) -> np.ndarray:
    """r = Log(Z⁻¹ Xᵢ⁻¹ Xⱼ) for every between edge."""
    return residuals_of(relative_poses(values, edges), edges)


def between_jacobians(relative: LieGroup, residuals: np.ndarray) -> np.ndarray:
    """[∂r/∂δᵢ ∂r/∂δⱼ] (m, d, 2d) of every between edge, ∂r/∂δᵢ = −jr⁻¹(r) Ad(Xⱼ⁻¹ Xᵢ) and
    ∂r/∂δⱼ = jr⁻¹(r), from its relative pose Xᵢ⁻¹ Xⱼ and residual."""
    jac_j = relative.jr_inv(residuals)
    d = jac_j.shape[-1]
    jacobians = np.empty(jac_j.shape[:-1] + (2 * d,))
    np.matmul(-jac_j, relative.inverse().adjoint(), out=jacobians[..., :d])
    jacobians[..., d:] = jac_j
    return jacobians


def prior_residuals(values: LieGroup, priors: EdgeSet) -> np.ndarray:
    """r = Log(Z⁻¹ X) for every prior."""
    return priors.measurements.between(values[priors.i]).log()


def linearize_between(values: LieGroup, edges: EdgeSet) -> Linearization:
    """Residuals and both Jacobians of every between edge."""
    relative = relative_poses(values, edges)
    residuals = residuals_of(relative, edges)
    return Linearization(residuals, between_jacobians(relative, residuals))


def linearize_priors(values: LieGroup, priors: EdgeSet) -> Linearization:
    """Residuals and Jacobians of every prior."""
    if len(priors) == 0:
        d = values.dof
        return Linearization(np.zeros((0, d)), np.zeros((0, d, d)))
    residuals = prior_residuals(values, priors)
    return Linearization(residuals, values.jr_inv(residuals))


def information_root(information: np.ndarray, inverse: bool = False) -> np.ndarray:
    """The symmetric square root W = Ω^½ of each (d, d) information matrix (W W = Ω), or with
    ``inverse`` the root of its pseudo-inverse, Ω^-½, which is zero along directions of zero
    information. From Ω = V diag(w) Vᵀ: W = V diag(w^±½) Vᵀ."""
    eigenvalues, eigenvectors = np.linalg.eigh(information)
    root = np.sqrt(eigenvalues.clip(min=0.0))
    if inverse:
        root = np.divide(
            1.0,
            root,
            out=np.zeros_like(root),
            where=root > 1e-12 * root.max(axis=-1, keepdims=True),
        )
    return (eigenvectors * root[..., None, :]) @ np.swapaxes(eigenvectors, -1, -2)


def weighted_squares(residuals: np.ndarray, information: np.ndarray) -> np.ndarray:
    """rᵀ Ω r of every edge."""
    return np.einsum("mi,mij,mj->m", residuals, information, residuals)


def between_squares(values: LieGroup, edges: EdgeSet) -> np.ndarray:
    """s = rᵀ Ω r of every between edge at ``values``."""
    return weighted_squares(between_residuals(values, edges), edges.information)


def prior_squares(values: LieGroup, priors: EdgeSet) -> np.ndarray:
    """s = rᵀ Ω r of every prior at ``values``."""
    if len(priors) == 0:
        return np.zeros(0)
    return weighted_squares(prior_residuals(values, priors), priors.information)


def chi2(values: LieGroup, edges: EdgeSet, priors: EdgeSet) -> float:
    """Σ rᵀ Ω r over between edges and priors (g2o's χ²); ``error`` is half of it."""
    return float(between_squares(values, edges).sum() + prior_squares(values, priors).sum())
