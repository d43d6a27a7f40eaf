"""Solver options (frozen, so a configuration can be shared and reused safely)."""

from __future__ import annotations

import dataclasses

import numpy as np

DEFAULT_INITIAL_DAMPING = 1e-12
"""Levenberg-Marquardt's λ at the start (relative: diagonal damping scales diag(H)). Small,
because the scale drift of a monocular Sim3 graph is a direction so soft that a larger λ holds
its steps short (ORB-SLAM's Sim3 essential graph starts g2o's λ at 1e-16); docs/architecture.md
gives the measurements behind the value."""


METHODS = ("lm", "gn", "dogleg")
"""The values of ``SolverOptions.method``."""


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """How ``optimize`` iterates and when it stops.

    Attributes:
        method: "lm" (Levenberg-Marquardt with Nielsen's gain-ratio damping update), "gn"
            (Gauss-Newton; a step that raises the error ends the run) or "dogleg" (Powell's
            dogleg in a trust region scaled by diag(H): one factorisation per linearisation,
            however many steps are rejected).
        max_iterations: most iterations, accepted or rejected.
        time_limit: seconds of wall-clock time after which the run stops (None: no limit).
        relative_decrease: stop when an accepted step lowers the error by less than this
            fraction of it, and (Levenberg-Marquardt) its quadratic model predicted no more;
            also when the model predicts less for the next (near) Gauss-Newton step.
        gradient_tolerance: stop when the largest gradient entry, max|Jᵀ Ω r|, falls below this.
        step_tolerance: stop when |δ| < step_tolerance · (|x| + step_tolerance), with |x| the norm
            of the stacked node tangents (Log of each value) at the start.
        damping: "diagonal" damps with λ·diag(H) (Marquardt, scale-invariant; after a rejected
            step, a node's directions that nothing measures with λ·max diag(H): see
            ``posegraph.solvers.loop``); "identity" with λ·I.
        initial_damping: λ at the start, relative to max diag(H) for "identity" damping. None:
            ``DEFAULT_INITIAL_DAMPING``, and in GNC's solves ``gnc.INITIAL_DAMPING``.
        min_diagonal, max_diagonal: clamp diag(H) before using it as damping (as Ceres does).
        linear_solver: "auto", "cholmod", "scipy" or "cg" (see ``posegraph.problem.backends``).
        skip_within: a ``Smoother``'s warm-started least-squares call solves nothing where the
            measurements added since its last solve could lower the cost by at most this share
            of it (``smoother.warm_start.skipped_debt``); 0 solves at every call.
    """

    method: str = "lm"
    max_iterations: int = 100
    time_limit: float | None = None
    relative_decrease: float = 1e-7
    gradient_tolerance: float = 1e-10
    step_tolerance: float = 1e-12
    damping: str = "diagonal"
    initial_damping: float | None = None
    min_diagonal: float = 1e-6
    max_diagonal: float = 1e32
    linear_solver: str = "auto"
    skip_within: float = 0.0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method is 'lm', 'gn' or 'dogleg', not {self.method!r}")
        if self.damping not in ("diagonal", "identity"):
            raise ValueError(f"damping is 'diagonal' or 'identity', not {self.damping!r}")
        if self.max_iterations < 0:
            raise ValueError("max_iterations must be ≥ 0")
        if self.time_limit is not None and not self.time_limit >= 0:
            raise ValueError(f"time_limit must be ≥ 0 seconds, not {self.time_limit}")
        for name in ("relative_decrease", "gradient_tolerance", "step_tolerance", "skip_within"):
            _require_finite_at_least(name, getattr(self, name), 0.0)
        if self.initial_damping is not None:
            _require_finite_at_least("initial_damping", self.initial_damping, 0.0)
        _require_finite_at_least("min_diagonal", self.min_diagonal, 0.0)
        _require_finite_at_least("max_diagonal", self.max_diagonal, self.min_diagonal)


def _require_finite_at_least(name: str, value: float, least: float) -> None:
    """Refuse a number that is not finite or is below ``least`` (NaN damping would make no
    step acceptable, and a NaN tolerance no stop reachable), naming the option."""
    if not (np.isfinite(value) and value >= least):
        raise ValueError(f"{name} must be a finite number ≥ {least:g}, not {value}")
