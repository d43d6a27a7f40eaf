"""SE3 → Sim3 lifting: similarities of scale 1, and information with a σ (log-scale) block."""

from __future__ import annotations

import numpy as np

from .lie import SE3, Sim3


def lift_se3(element: SE3, scale: float | np.ndarray = 1.0) -> Sim3:
    """The similarities (R, t, s) of SE3 elements, with scale ``scale``."""
    batch = element.batch_shape
    return Sim3(
        element.rotation, element.translation, np.broadcast_to(np.asarray(scale, float), batch)
    )


def check_scale_information(scale_information: float | None) -> None:
    """Refuse a log-scale information that is not a positive finite number (None: the default)."""
    if scale_information is not None and not 0 < scale_information < np.inf:
        raise ValueError(
            f"scale information must be positive and finite, not {scale_information:g}"
        )


def lift_information(information: np.ndarray, scale_information: float) -> np.ndarray:
    """(…, 7, 7) Sim3 information over (ρ, φ, σ) from (…, 6, 6) SE3 information over (ρ, φ)."""
    information = np.asarray(information, float)
    out = np.zeros(information.shape[:-2] + (7, 7))
    out[..., :6, :6] = information
    out[..., 6, 6] = scale_information
    return out


def default_scale_information(se3_information: np.ndarray, se3_measurements: SE3) -> float:
    """Information on log-scale for lifted SE3 edges: median over edges of λ_t · |Δt|², with
    λ_t = tr(Ω_ρρ)/3, so that a relative scale change costs about as much as the translation
    error it could explain. Much weaker and node scales absorb translation residuals (the
    positions are then barely constrained); much stronger and loops cannot re-scale."""
    if len(se3_information) == 0:
        return 1.0
    translation_weight = np.trace(se3_information[:, :3, :3], axis1=1, axis2=2) / 3.0
    step = np.einsum("mi,mi->m", se3_measurements.translation, se3_measurements.translation)
    value = float(np.median(translation_weight * step))
    return value if value > 0 else 1.0
