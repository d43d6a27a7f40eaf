"""The step strategies of the iteration loop (``loop``): Levenberg-Marquardt (and Gauss-Newton,
undamped) and Powell's dogleg, each proposing a step from the normal equations and updating its
damping or trust region by the gain ratio (the module docstring of ``loop`` gives the rules)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..graph import PoseGraph
from ..problem.cholesky import NotPositiveDefinite
from ..problem.observability import describe_unmeasured, unmeasured_directions, unmeasured_share
from .options import DEFAULT_INITIAL_DAMPING, SolverOptions


@dataclasses.dataclass(frozen=True)
class Proposal:
    """A step δ over the free coordinates and what the quadratic model m(δ) = gᵀδ + ½ δᵀHδ
    predicts of it."""

    step: np.ndarray
    predicted: float
    """The model's decrease, −m(δ)."""
    ok: bool
    """Whether there is a step (finite; False where nothing factorised)."""
    singular: bool
    """Whether the matrix to factorise was not positive definite."""
    newton: bool
    """Whether δ is (nearly) the Gauss-Newton step and the last factorisation (nearly) H's, so
    that its solves give the Newton decrement."""


def _damping_scale(
    options: SolverOptions, diagonal: np.ndarray, unmeasured: np.ndarray | None
) -> np.ndarray:
    """D of the damping λD (and of the dogleg's region): diag(H) clamped to ``min_diagonal``
    … ``max_diagonal``, and at least ``unmeasured`` (each free coordinate's share of directions
    that nothing measures, once found) times max diag(H) (module docstring); I for "identity"
    damping."""
    if options.damping != "diagonal":
        return np.ones_like(diagonal)
    scale = np.clip(diagonal, options.min_diagonal, options.max_diagonal)
    if unmeasured is not None:
        scale = np.maximum(scale, unmeasured * diagonal.max())
    return scale


def inner(a: np.ndarray, b: np.ndarray) -> float:
    """aᵀb of two vectors, summed by numpy's own loop: ``a @ b`` calls BLAS's ``ddot``, which
    OpenBLAS splits over threads from 10,000 entries, and whose threads can wait milliseconds
    for each other on a machine whose cores are busy."""
    return float(np.einsum("i,i->", a, b))


def _unmeasured_share(graph: PoseGraph, system) -> np.ndarray:
    """Each free coordinate's share of directions that nothing measures at first order
    (``observability.unmeasured_share``; module docstring), in ``system``'s variable order."""
    return system.gather(unmeasured_share(graph))


class _LevenbergMarquardt:
    """Steps from (H + λD) δ = −g, with λ updated by the gain ratio (module docstring); with
    ``damped`` False, Gauss-Newton (λ = 0): a rejected step ends the run."""

    def __init__(self, options: SolverOptions, diagonal: np.ndarray, damped: bool = True) -> None:
        self.options, self.damped = options, damped
        initial = options.initial_damping
        self.lam = DEFAULT_INITIAL_DAMPING if initial is None else initial
        if options.damping == "identity":
            self.lam *= float(diagonal.max())
        self.nu = 2.0
        # Per free coordinate, its share of directions that nothing measures (module
        # docstring): found at the first rejected step, so a run that rejects none does not
        # pay for it.
        self.unmeasured = None

    @property
    def damping(self) -> float:
        """λ (0 for Gauss-Newton), as the iteration records give it."""
        return self.lam if self.damped else 0.0

    def propose(self, graph, system, data, gradient, diagonal, fresh, clock) -> Proposal:
        options, lam = self.options, self.lam
        scale = _damping_scale(options, diagonal, self.unmeasured)
        singular = False
        try:
            system.factorize(data, lam * scale if self.damped else None)
            clock.lap("factorize")
            step = system.solve(-gradient)
            clock.lap("solve")
            step_ok = bool(np.all(np.isfinite(step)))
        except NotPositiveDefinite:
            clock.lap("factorize")
            step, step_ok, singular = np.zeros_like(gradient), False, True
        damping_share = (
            np.max(lam * scale / np.maximum(diagonal, options.min_diagonal)) if self.damped else 0.0
        )
        predicted = 0.5 * inner(step, (lam * scale * step if self.damped else 0.0) - gradient)
        return Proposal(step, predicted, step_ok, singular, bool(damping_share < 1e-3))

    def update(self, accepted: bool, decrease: float, proposal: Proposal) -> None:
        if not self.damped:
            return
        if accepted:
            predicted = proposal.predicted
            rho = decrease / predicted if predicted > 0 else 0.0
            self.lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            self.nu = 2.0
        else:
            self.lam *= self.nu
            self.nu *= 2.0

    def rejected(self, graph, system, proposal: Proposal, trial) -> str | None:
        """Why the run ends after a rejected step, or None to try again."""
        if not self.damped:
            if proposal.singular:
                return _singular_termination(graph)
            if trial is not None and not np.isfinite(trial.error):
                return (
                    "step overflowed double precision (Gauss-Newton does not damp it,"
                    " Levenberg-Marquardt does)"
                )
            return "step raised the error (Gauss-Newton)"
        if not np.isfinite(self.lam) or self.lam > self.options.max_diagonal:
            return "damping exceeded its limit (no step lowers the error)"
        if self.unmeasured is None and self.options.damping == "diagonal":
            self.unmeasured = _unmeasured_share(graph, system)
        return None


class _Dogleg:
    """Powell's dogleg in the trust region ‖D^½ δ‖ ≤ Δ, D Levenberg-Marquardt's damping scale
    (``_damping_scale``; Madsen, Nielsen & Tingleff 2004, §3.3; a scaled region as Moré 1983
    and Ceres use). Per linearisation, H is factorised once for the Gauss-Newton step δ_gn;
    the Cauchy step δ_sd = −α D⁻¹g, α = gᵀD⁻¹g / (D⁻¹g)ᵀH(D⁻¹g), minimises the model along
    the scaled steepest descent. The step is δ_gn inside the region, δ_sd cut to it if that
    leaves it (or where H does not factorise), else the point where the segment from δ_sd to
    δ_gn crosses it. A rejected step shrinks Δ and proposes again from the same factorisation.
    Δ starts at the first step's norm; after a step, Δ ← max(Δ, 3‖δ‖) where the gain ratio
    ρ > 0.75, and Δ ← ‖δ‖/2 where ρ < 0.25.

    From the first rejected step (or failed factorisation) on, directions that nothing
    measures at first order (module docstring) are held back: H + U is factorised, U their
    share times max diag(H), so that δ_gn barely moves along them, and D weighs them as U."""

    damped = True

    def __init__(self, options: SolverOptions) -> None:
        self.options = options
        self.radius: float | None = None
        self.unmeasured = None
        self._stale = False  # ``unmeasured`` was found after the last factorisation

    @property
    def damping(self) -> float:
        """Δ, as the iteration records give it."""
        return float(self.radius)

    def propose(self, graph, system, data, gradient, diagonal, fresh, clock) -> Proposal:
        if fresh or self._stale:
            self._linearize(graph, system, data, gradient, diagonal, clock)
        gauss_newton, cauchy, radius = self._gauss_newton, self._cauchy, self.radius
        if gauss_newton is not None and self._norm(gauss_newton) <= radius:
            step = gauss_newton
        elif gauss_newton is None or self._norm(cauchy) >= radius:
            step = cauchy * (radius / self._norm(cauchy))
        else:
            step = cauchy + self._toward_boundary(cauchy, gauss_newton, radius) * (
                gauss_newton - cauchy
            )
        predicted = -inner(gradient, step) - 0.5 * inner(step, self._hessian @ step)
        clock.lap("solve")
        self._scaled_norm = self._norm(step)
        newton = step is gauss_newton and self._held_back is None
        ok = bool(np.all(np.isfinite(step)))
        return Proposal(step, predicted, ok, gauss_newton is None, newton)

    def _linearize(self, graph, system, data, gradient, diagonal, clock) -> None:
        """δ_gn and δ_sd at a linearisation (H's CSC ``data``), finding the directions that
        nothing measures if H does not factorise."""
        self._gauss_newton = self._solve(system, data, gradient, diagonal, clock)
        if self._gauss_newton is None and self.unmeasured is None:
            self.unmeasured = _unmeasured_share(graph, system)
            self._gauss_newton = self._solve(system, data, gradient, diagonal, clock)
        self._stale = False
        self._hessian = system.matrix(data)
        direction = gradient / self._scale
        curvature = inner(direction, self._hessian @ direction)
        alpha = inner(gradient, direction) / curvature if curvature > 0 else np.inf
        self._cauchy = -alpha * direction if np.isfinite(alpha) else -direction
        if self.radius is None:
            start = self._gauss_newton if self._gauss_newton is not None else self._cauchy
            self.radius = self._norm(start)

    def _solve(self, system, data, gradient, diagonal, clock) -> np.ndarray | None:
        """δ_gn from H + U (U zero until ``unmeasured`` is known); None if it does not
        factorise or its solution is not finite."""
        self._scale = _damping_scale(self.options, diagonal, self.unmeasured)
        held_back = None
        if self.unmeasured is not None and self.unmeasured.any():
            held_back = self.unmeasured * diagonal.max()
        self._held_back = held_back
        try:
            system.factorize(data, held_back)
            clock.lap("factorize")
            step = system.solve(-gradient)
        except NotPositiveDefinite:
            clock.lap("factorize")
            return None
        return step if np.all(np.isfinite(step)) else None

    def _norm(self, step: np.ndarray) -> float:
        """‖D^½ δ‖."""
        return float(np.sqrt(inner(step, self._scale * step)))

    def _toward_boundary(self, inside: np.ndarray, outside: np.ndarray, radius: float) -> float:
        """β in [0, 1] with ‖D^½ (a + β (b − a))‖ = Δ, for a inside the region and b outside."""
        between = outside - inside
        a = inner(between, self._scale * between)
        b = 2.0 * inner(inside, self._scale * between)
        c = inner(inside, self._scale * inside) - radius * radius
        return (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)

    def update(self, accepted: bool, decrease: float, proposal: Proposal) -> None:
        rho = decrease / proposal.predicted if accepted and proposal.predicted > 0 else 0.0
        if rho > 0.75:
            self.radius = max(self.radius, 3.0 * self._scaled_norm)
        elif rho < 0.25:
            self.radius = 0.5 * self._scaled_norm

    def rejected(self, graph, system, proposal: Proposal, trial) -> str | None:
        """Why the run ends after a rejected step, or None to try again."""
        if not (np.isfinite(self.radius) and self.radius > 0.0):
            return "trust region collapsed (no step lowers the error)"
        if self.unmeasured is None and self.options.damping == "diagonal":
            self.unmeasured = _unmeasured_share(graph, system)
            self._stale = bool(self.unmeasured.any())
        return None


STEPS = {
    "lm": _LevenbergMarquardt,
    "gn": functools.partial(_LevenbergMarquardt, damped=False),
    "dogleg": lambda options, diagonal: _Dogleg(options),
}
"""The step strategy of each ``SolverOptions.method``, from the options and diag(H) at the
start (Levenberg-Marquardt's identity damping scales λ by its largest entry)."""


def _singular_termination(graph: PoseGraph) -> str:
    """Why Gauss-Newton stopped when H did not factorise, naming the nodes with directions that
    no measurement reaches (``posegraph.problem.observability``), if there are any."""
    counts = unmeasured_directions(graph)
    where = f" ({describe_unmeasured(graph, counts)})" if counts.any() else ""
    return (
        f"normal equations singular: some direction is measured by nothing{where};"
        " Gauss-Newton does not damp it, Levenberg-Marquardt does"
    )
