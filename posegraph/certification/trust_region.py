"""Riemannian trust-region minimisation of F(Y) = tr(Y Q Yᵀ) on St(d, r)ⁿ, with the
Steihaug-Toint truncated conjugate gradient for each step (Absil, Baker and Gallivan 2007,
Algorithms 1–2; SE-Sync §4.1.2). Gradient and Hessian are SE-Sync's eqs. 42–44:
grad F = P_Y(2 Y Q) and Hess F[V] = P_Y(2 V Q − V SymBlockDiag(Yᵀ 2 Y Q)). At rank d the
steps are preconditioned by Newton's system over poses (``poses``), which holds pose 0 and so
leaves out the global rotation; above it by (Q + εI)⁻¹ (SE-Sync's regularised Cholesky
preconditioner). (Q − Λ + εI)⁻¹ was tried above rank d and is slower: near the minimum it is
nearly singular along the global rotation, a direction of zero curvature that CG then chases."""

from __future__ import annotations

import dataclasses

import numpy as np

from .data import SESyncData
from .poses import PosePreconditioner
from .stiefel import blocks, joined, project, retract, sym_block_products

ACCEPT = 0.1
"""A step is taken when the actual decrease is at least this share of the model's."""
MAX_INNER = 500
"""Most conjugate-gradient iterations per step."""
ROUND_OFF = 1e-14
"""F = tr(Y Q Yᵀ) sums terms of Q's size (``SESyncData.scale``), n of them per row: a step
whose model decrease is below this × scale × n is lost in F's round-off, and is taken only if
it lowers the gradient's norm (a Newton step near the minimum), else the minimisation stops."""


@dataclasses.dataclass(frozen=True)
class Minimum:
    """Where the trust region stopped: the point, F there, the gradient's norm, iterations."""

    y: np.ndarray
    objective: float
    gradient_norm: float
    iterations: int


def minimize(
    data: SESyncData, y: np.ndarray, gradient_tolerance: float, max_iterations: int = 500
) -> Minimum:
    """Minimise F from ``y`` until the Riemannian gradient's norm is below
    ``gradient_tolerance`` (or ``max_iterations``)."""
    d = data.d
    yq = data.product(y)
    value = float(np.sum(y * yq))
    radius = None
    poses = PosePreconditioner(data) if y.shape[0] == d else None
    for iteration in range(max_iterations):
        gradient = project(y, 2.0 * yq, d)
        norm = float(np.linalg.norm(gradient))
        if norm <= gradient_tolerance:
            return Minimum(y, value, norm, iteration)
        if radius is None:
            radius = max(norm, 1.0) * 10.0
        curvature = sym_block_products(y, 2.0 * yq, d)

        def hessian(v: np.ndarray, y=y, curvature=curvature) -> np.ndarray:
            return project(y, 2.0 * data.product(v) - joined(blocks(v, d) @ curvature), d)

        precondition, measure = _preconditioner(data, y, poses, 0.5 * curvature)
        step, model_decrease, on_boundary = _truncated_cg(
            gradient, hessian, precondition, radius, norm, measure
        )
        candidate = retract(y, step, d)
        candidate_yq = data.product(candidate)
        candidate_value = float(np.sum(candidate * candidate_yq))
        if model_decrease <= ROUND_OFF * data.scale * data.n:  # F cannot tell: the gradient
            if np.linalg.norm(project(candidate, 2.0 * candidate_yq, d)) >= norm:
                return Minimum(y, value, norm, iteration)
            y, yq, value = candidate, candidate_yq, candidate_value
            continue
        ratio = (value - candidate_value) / model_decrease if model_decrease > 0 else -1.0
        if ratio < 0.25:
            radius /= 4.0
        elif ratio > 0.75 and on_boundary:
            radius *= 2.0
        if ratio > ACCEPT:
            y, yq, value = candidate, candidate_yq, candidate_value
    gradient = project(y, 2.0 * yq, d)
    return Minimum(y, value, float(np.linalg.norm(gradient)), max_iterations)


def _preconditioner(
    data: SESyncData, y: np.ndarray, poses: PosePreconditioner | None, multipliers: np.ndarray
):
    """(V ↦ P_Y(V (Q + εI)⁻¹), ‖·‖), or at rank d (``poses``) the pose system factorised at Y
    (Λ's blocks ``multipliers``) with the norm its conjugate gradients are stopped by."""
    if poses is not None:
        poses.factorize(y, multipliers)
        return poses, poses.residual_norm
    return (lambda v: project(y, data.precondition(v), data.d)), np.linalg.norm


def _truncated_cg(gradient, hessian, precondition, radius: float, norm: float, measure):
    """Steihaug-Toint CG for the model m(η) = ⟨g, η⟩ + ½⟨η, H η⟩ within ‖η‖ ≤ radius,
    preconditioned, stopped at ‖r‖ ≤ ‖g‖ min(‖g‖, 0.1) (superlinear convergence, Absil et al.
    eq. 10; ‖r‖ by ``measure``). Returns (η, the model's decrease −m(η), whether the step
    reached the boundary)."""
    eta = np.zeros_like(gradient)
    h_eta = np.zeros_like(gradient)
    residual = gradient.copy()
    z = precondition(residual)
    direction = -z
    r_z = float(np.sum(residual * z))
    target = norm * min(norm, 0.1)
    on_boundary = False
    for _ in range(MAX_INNER):
        h_d = hessian(direction)
        d_h_d = float(np.sum(direction * h_d))
        alpha = r_z / d_h_d if d_h_d > 0 else np.inf
        if d_h_d <= 0 or np.linalg.norm(eta + alpha * direction) >= radius:
            tau = _to_boundary(eta, direction, radius)
            eta, h_eta = eta + tau * direction, h_eta + tau * h_d
            on_boundary = True
            break
        eta, h_eta = eta + alpha * direction, h_eta + alpha * h_d
        residual = residual + alpha * h_d
        if measure(residual) <= target:
            break
        z = precondition(residual)
        new_r_z = float(np.sum(residual * z))
        direction = -z + (new_r_z / r_z) * direction
        r_z = new_r_z
    decrease = -(float(np.sum(gradient * eta)) + 0.5 * float(np.sum(eta * h_eta)))
    return eta, decrease, on_boundary


def _to_boundary(eta: np.ndarray, direction: np.ndarray, radius: float) -> float:
    """τ ≥ 0 with ‖η + τ p‖ = radius."""
    a = float(np.sum(direction * direction))
    b = 2.0 * float(np.sum(eta * direction))
    c = float(np.sum(eta * eta)) - radius**2
    return (-b + np.sqrt(max(b * b - 4 * a * c, 0.0))) / (2 * a)
