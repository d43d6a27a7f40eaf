"""Robust kernels applied as iteratively reweighted least squares (IRLS).

Every kernel is a function ρ of the squared Mahalanobis distance s = rᵀ Ω r of an edge, with
ρ(s) = s for small s, so that the robust cost is ½ Σ ρ(sₑ) and reduces to ½ Σ sₑ. Each iteration
weighs an edge's information by w = ρ′(s) at the current values (Triggs et al. 2000 §4.3;
Zach 2014). ``width`` c is in units of the residual (s is compared with c²).

| kernel | ρ(s) | w = ρ′(s) |
|---|---|---|
| Huber | s if s ≤ c², else 2c√s − c² | 1, else c/√s |
| Cauchy | c² log(1 + s/c²) | 1/(1 + s/c²) |
| Geman-McClure | c² s/(c² + s) | c⁴/(c² + s)² |
| Tukey | c²/3 (1 − (1 − s/c²)³) if s ≤ c², else c²/3 | (1 − s/c²)², else 0 |
| DCS (Agarwal et al. 2013) | s if s ≤ c², else c²(3s − c²)/(s + c²) | 1, else 4c⁴/(s + c²)² |
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .chi_square import chi2_quantile

KERNELS = ("huber", "cauchy", "geman-mcclure", "tukey", "dcs")


@dataclasses.dataclass(frozen=True)
class RobustKernel:
    """A kernel by name and width c (residual units): one for every s, or one per s (an array
    of the shape of the s it is applied to)."""

    name: str
    width: float | np.ndarray

    def __post_init__(self) -> None:
        if self.name not in KERNELS:
            raise ValueError(
                f"unknown robust kernel {self.name!r}; choose from {', '.join(KERNELS)}"
            )
        if not np.all(np.asarray(self.width) > 0):
            raise ValueError(f"a robust kernel's width must be positive, not {self.width}")

    def cost(self, s: np.ndarray) -> np.ndarray:
        """ρ(s)."""
        c2 = self.width**2
        if self.name == "huber":
            return np.where(s <= c2, s, 2.0 * self.width * np.sqrt(np.maximum(s, c2)) - c2)
        if self.name == "cauchy":
            return c2 * np.log1p(s / c2)
        if self.name == "geman-mcclure":
            return c2 * s / (c2 + s)
        if self.name == "tukey":
            return np.where(s <= c2, c2 / 3.0 * (1.0 - (1.0 - s / c2) ** 3), c2 / 3.0)
        return np.where(s <= c2, s, c2 * (3.0 * s - c2) / (s + c2))

    def weight(self, s: np.ndarray) -> np.ndarray:
        """w = ρ′(s)."""
        c2 = self.width**2
        if self.name == "huber":
            return np.where(s <= c2, 1.0, self.width / np.sqrt(np.maximum(s, c2)))
        if self.name == "cauchy":
            return 1.0 / (1.0 + s / c2)
        if self.name == "geman-mcclure":
            return c2**2 / (c2 + s) ** 2
        if self.name == "tukey":
            return np.where(s <= c2, (1.0 - s / c2) ** 2, 0.0)
        return np.where(s <= c2, 1.0, 4.0 * c2**2 / (s + c2) ** 2)


def default_width(dof: int, quantile: float = 0.99) -> float:
    """√χ²_dof(quantile): the residual size an inlier of ``dof`` dimensions exceeds with
    probability 1 − quantile (``chi_square.chi2_quantile``)."""
    return math.sqrt(chi2_quantile(dof, quantile))


@dataclasses.dataclass(frozen=True)
class Robustifier:
    """A kernel applied to a subset of the between edges (``mask``); other edges stay ½ s."""

    kernel: RobustKernel
    mask: np.ndarray

    def cost_and_weights(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-edge ρ(s) and w, with ρ = s and w = 1 outside the mask."""
        cost, weights = s.copy(), np.ones_like(s)
        cost[self.mask] = self.kernel.cost(s[self.mask])
        weights[self.mask] = self.kernel.weight(s[self.mask])
        return cost, weights


def tls_gnc_weights(s: np.ndarray, width_sq: float | np.ndarray, mu: float) -> np.ndarray:
    """Weights of the truncated-least-squares kernel's GNC surrogate (Yang, Antonante, Tzoumas &
    Carlone 2020, "Graduated Non-Convexity for Robust Spatial Perception", eq. 14):
    1 for s ≤ μ c²/(μ+1), 0 for s ≥ (μ+1) c²/μ, and c √(μ(μ+1)/s) − μ between."""
    inner, outer = mu / (mu + 1.0) * width_sq, (mu + 1.0) / mu * width_sq
    between = np.sqrt(width_sq * mu * (mu + 1.0) / np.maximum(s, inner)) - mu
    return np.where(s <= inner, 1.0, np.where(s >= outer, 0.0, between))
