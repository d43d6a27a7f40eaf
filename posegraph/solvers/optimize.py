"""Gauss-Newton, Levenberg-Marquardt and Powell's dogleg over the fixed-pattern normal equations.

One loop serves all three; each method proposes steps (``_LevenbergMarquardt``, ``_Dogleg``).
Each iteration tries X ⊕ δ (right retraction on every free node) and accepts the step only if
the error is finite and lower. Levenberg-Marquardt's step solves (H + λD) δ = −g, with λ = 0
for Gauss-Newton, and updates λ by the gain ratio
ρ = (actual decrease) / (predicted decrease ½ δᵀ(λDδ − g)): on success
λ ← λ·max(1/3, 1 − (2ρ − 1)³) and ν ← 2; on failure λ ← λ·ν and ν ← 2ν
(Nielsen 1999; Madsen, Nielsen & Tingleff 2004, §3.2).
A rejected step costs a refactorisation and an evaluation of the residuals: the Jacobians
are computed only at accepted values, and the linearisation is kept. The dogleg's rejected
step costs the evaluation alone: its trust region shrinks about the same factorisation.

Marquardt's D = diag(H) scales the damping with the curvature. A direction that no measurement
reaches at first order (``posegraph.observability``: the rotation of a pose seen only by
position-only edges) still has a little curvature where residuals are not zero, through the
Log's coupling, so its damped steps are huge and rejected one after another: such a pose made
Levenberg-Marquardt crawl for 100 iterations. From the first rejected step on, those directions
are damped by λ max diag(H), as identity damping (gtsam's and g2o's default) would.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from ..factors import (
    Linearization,
    between_jacobians,
    linearize_priors,
    relative_poses,
    residuals_of,
    weighted_squares,
)
from ..graph import PoseGraph
from ..lie import LieGroup
from ..linear import NormalEquations
from ..observability import describe_unmeasured, unmeasured_directions, unmeasured_share
from ..sparse_cholesky import NotPositiveDefinite
from .options import DEFAULT_INITIAL_DAMPING, SolverOptions
from .summary import PHASES, IterationRecord, Result, Summary

Callback = Callable[[IterationRecord], bool | None]
"""Called after every iteration; returning True stops the run (termination ``STOPPED``)."""
STOPPED = "stopped by callback"
TIME_LIMIT = "time limit reached"
MAX_ITERATIONS = "maximum iterations reached"
NOT_FINITE = "the error at the start is not finite (values or residuals beyond double precision)"


class _Clock:
    """Accumulates wall-clock time per phase."""

    def __init__(self) -> None:
        self.start = time.perf_counter()
        self.times = dict.fromkeys(PHASES, 0.0)
        self._mark = self.start

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.times[phase] += now - self._mark
        self._mark = now

    def elapsed(self) -> float:
        return time.perf_counter() - self.start


class EdgeWeighting(Protocol):
    """Turns the between edges' s = rᵀΩr into their costs ρ(s) and IRLS weights ρ′(s)."""

    def cost_and_weights(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


class _Linearized:
    """Residuals and error ½ (Σ ρ(s) + Σ s_prior) of the whole graph at some values, the between
    edges' information weighted for IRLS, and their Jacobians (``between``, computed on first
    use: a rejected step never needs them).

    ``previous``, a linearisation of this graph before edges were appended, is reused for its
    edges if their nodes still have the values it was taken at (a warm start).

    ``normal_matrix`` is H's CSC data at these values once the solver has assembled it (None
    before), which covariances at the solution reuse (``normal_matrix_for``).
    """

    def __init__(
        self,
        graph: PoseGraph,
        values: LieGroup,
        weighting: EdgeWeighting | None,
        previous: _Linearized | None = None,
    ) -> None:
        self.values, self.edges, self.prior_edges = values, graph.edges, graph.priors
        self.weighted = weighting is not None
        self.normal_matrix: np.ndarray | None = None
        reused = previous is not None and previous._holds_for(graph.edges, values)
        self.reused_edges = len(previous.edges) if reused else 0
        # Without reuse, every edge is "appended" (and the edge set is not copied).
        appended = graph.edges.subset(slice(self.reused_edges, None)) if reused else graph.edges
        self._relative = relative_poses(values, appended)
        self._residuals = residuals_of(self._relative, appended)
        self._reused = previous.between if reused else None
        squared = weighted_squares(self._residuals, appended.information)
        if reused:
            squared = np.concatenate([previous.squared, squared])
        self.squared = squared
        self.priors: Linearization = linearize_priors(values, graph.priors)
        prior_total = weighted_squares(self.priors.residuals, graph.priors.information).sum()
        if weighting is None:
            self.information = graph.edges.information
            self.error = 0.5 * float(self.squared.sum() + prior_total)
        else:
            cost, weights = weighting.cost_and_weights(self.squared)
            self.information = graph.edges.information * weights[:, None, None]
            self.error = 0.5 * float(cost.sum() + prior_total)

    @functools.cached_property
    def between(self) -> Linearization:
        """Residuals and Jacobians of every between edge."""
        jacobians = between_jacobians(self._relative, self._residuals)
        appended = Linearization(self._residuals, jacobians)
        return appended if self._reused is None else self._reused.extended(appended)

    def normal_matrix_for(self, graph: PoseGraph, values: LieGroup) -> np.ndarray | None:
        """``normal_matrix``, if it is H of ``graph`` at ``values``: assembled at exactly these
        values, over exactly the graph's edges and priors, in least squares (no IRLS weights);
        else None."""
        if self.normal_matrix is None or self.weighted:
            return None
        same = (
            len(values) == len(self.values)
            and values.same_as(self.values)
            and len(graph.edges) == len(self.edges)
            and graph.edges.starts_with(self.edges)
            and len(graph.priors) == len(self.prior_edges)
            and graph.priors.starts_with(self.prior_edges)
        )
        return self.normal_matrix if same else None

    def _holds_for(self, edges, values: LieGroup) -> bool:
        """Whether this linearisation is that of the first edges of ``edges`` at ``values``."""
        count = len(self.values)
        return (
            count <= len(values)
            and edges.starts_with(self.edges)
            and values[:count].same_as(self.values)
        )


def optimize(
    graph: PoseGraph,
    options: SolverOptions | None = None,
    callback: Callback | None = None,
    system: NormalEquations | None = None,
    weighting: EdgeWeighting | None = None,
    previous: Result | None = None,
) -> Result:
    """Minimise ½ Σ rᵀΩr over the graph's free nodes, starting from ``graph.values``.

    The gauge is ``graph.gauge_nodes()`` (fixed nodes, or the lowest id of each component
    without a prior). ``system`` passes in a ``NormalEquations`` built earlier for the same
    structure, to reuse its pattern and symbolic factorisation. ``previous``, the result of
    an earlier call on this graph, warm-starts: its pattern is grown if the graph grew by
    appending, and its linearisation is reused where the graph's edges and values are
    unchanged (its residuals and Jacobians: the weights are taken anew). ``weighting`` makes
    the cost robust (``posegraph.robust.Robustifier``: IRLS, its weights re-evaluated at every
    linearisation). The graph is not modified.
    """
    options = SolverOptions() if options is None else options
    clock = _Clock()
    reused = []
    if system is None:
        grow_from = None if previous is None else previous.system
        system = NormalEquations(
            graph, graph.gauge_nodes(), options.linear_solver, previous=grow_from
        )
        if system.grown:
            reused = ["sparsity pattern (grown)"]
    else:
        reused = ["sparsity pattern", "symbolic factorization"]

    clock.lap("other")
    last = None if previous is None else previous.linearization
    current = _Linearized(graph, graph.values, weighting, last)
    if current.reused_edges:
        reused.append(f"linearization of {current.reused_edges} edges")
    clock.lap("linearize")
    initial_error = current.error
    history: list[IterationRecord] = []

    if system.size == 0:
        termination, converged = "nothing to optimise", True
    elif not np.isfinite(initial_error):
        termination, converged = NOT_FINITE, False
    elif options.max_iterations == 0:
        termination, converged = MAX_ITERATIONS, False
    else:
        current, termination, converged = _iterate(
            graph, options, callback, system, weighting, clock, current, history
        )
    clock.lap("other")
    summary = Summary(
        method=options.method,
        linear_solver=system.cholesky.name,
        initial_error=initial_error,
        final_error=current.error,
        iterations=history,
        termination=termination,
        converged=converged,
        phase_times=dict(clock.times),
        total_time=clock.elapsed(),
        num_variables=system.size,
        reused=reused,
    )
    return Result(current.values, summary, system, current)


def _assemble(graph, system, current, clock):
    """H's CSC data (kept as ``current.normal_matrix``), the gradient and diag(H) at
    ``current`` (its Jacobians timed as linearisation)."""
    between = current.between
    clock.lap("linearize")
    data, gradient = system.assemble(
        between, current.information, current.priors, graph.priors.information
    )
    current.normal_matrix = data
    clock.lap("assemble")
    return data, gradient, system.diagonal(data)


def _iterate(graph, options, callback, system, weighting, clock, current, history):
    """The iterations of ``optimize``; returns (final linearisation, termination, converged).
    ``history`` receives a record per iteration."""
    termination, converged = MAX_ITERATIONS, False
    data, gradient, diagonal = _assemble(graph, system, current, clock)
    steps = _STEPS[options.method](options, diagonal)
    fresh = True  # a linearisation not yet proposed from
    # |x| of the step test, at the start: it changes little over a run, and a Log of every
    # node per iteration would cost as much as a linearisation on small graphs.
    size = float(np.linalg.norm(current.values.log()))

    for iteration in range(1, options.max_iterations + 1):
        if np.max(np.abs(gradient)) < options.gradient_tolerance:
            termination, converged = "gradient below tolerance", True
            break
        if options.time_limit is not None and clock.elapsed() > options.time_limit:
            termination = TIME_LIMIT
            break
        proposal = steps.propose(graph, system, data, gradient, diagonal, fresh, clock)
        fresh = False
        if (
            proposal.ok
            and proposal.newton
            and 0 <= proposal.predicted <= options.relative_decrease * current.error
        ):
            # A (near) Gauss-Newton step whose quadratic model promises less than the tolerance:
            # stop without spending a linearisation on evaluating it.
            termination, converged = "predicted error decrease below tolerance", True
            break
        trial = None
        if proposal.ok:
            # A step far beyond the quadratic model's reach (along a direction measured only
            # weakly) can overflow, as a Sim3 scale of e^800: its error is then not finite,
            # and the step is rejected.
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                trial_values = current.values.retract(system.scatter(proposal.step))
                trial = _Linearized(graph, trial_values, weighting)
            clock.lap("linearize")
        step_norm = float(np.linalg.norm(proposal.step))
        accepted = bool(
            trial is not None and np.isfinite(trial.error) and trial.error < current.error
        )
        decrease = current.error - trial.error if accepted else 0.0
        steps.update(accepted, decrease, proposal)
        if accepted:
            previous_error, current = current.error, trial
        record = IterationRecord(
            iteration, current.error, steps.damping, step_norm, accepted, clock.elapsed()
        )
        history.append(record)
        if callback is not None and callback(record):
            termination = STOPPED
            break
        small = step_norm < options.step_tolerance * (size + options.step_tolerance)
        if not accepted and proposal.ok and small:
            # A step that changes the values only at rounding level and still does not lower
            # the error: the error is at its floating-point floor (a map in UTM coordinates,
            # whose residuals cannot fall below about 1e-9 m), as Ceres's parameter tolerance.
            termination, converged = "step below tolerance", True
            break
        if not accepted:
            stop = steps.rejected(graph, system, proposal, trial)
            if stop is not None:
                termination = stop
                break
            continue
        if decrease <= options.relative_decrease * previous_error and (
            not steps.damped or proposal.predicted <= options.relative_decrease * previous_error
        ):
            termination, converged = "relative error decrease below tolerance", True
            break
        if small:
            termination, converged = "step below tolerance", True
            break
        data, gradient, diagonal = _assemble(graph, system, current, clock)
        fresh = True
        if proposal.newton:
            # The Newton decrement ½ gᵀH⁻¹g at the new values, with H from the factorisation
            # just used (its change over a converging step is second order): when it promises
            # less than the tolerance, the run has converged without a new factorisation.
            estimate = 0.5 * float(gradient @ system.solve(gradient))
            clock.lap("solve")
            if 0 <= estimate <= options.relative_decrease * current.error:
                termination, converged = "predicted error decrease below tolerance", True
                break
    return current, termination, converged


@dataclasses.dataclass(frozen=True)
class _Proposal:
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

    def propose(self, graph, system, data, gradient, diagonal, fresh, clock) -> _Proposal:
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
        predicted = 0.5 * float(step @ ((lam * scale * step if self.damped else 0.0) - gradient))
        return _Proposal(step, predicted, step_ok, singular, bool(damping_share < 1e-3))

    def update(self, accepted: bool, decrease: float, proposal: _Proposal) -> None:
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

    def rejected(self, graph, system, proposal: _Proposal, trial) -> str | None:
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

    def propose(self, graph, system, data, gradient, diagonal, fresh, clock) -> _Proposal:
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
        predicted = -float(gradient @ step) - 0.5 * float(step @ (self._hessian @ step))
        clock.lap("solve")
        self._scaled_norm = self._norm(step)
        newton = step is gauss_newton and self._held_back is None
        ok = bool(np.all(np.isfinite(step)))
        return _Proposal(step, predicted, ok, gauss_newton is None, newton)

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
        curvature = float(direction @ (self._hessian @ direction))
        alpha = float(gradient @ direction) / curvature if curvature > 0 else np.inf
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
        return float(np.sqrt(step @ (self._scale * step)))

    def _toward_boundary(self, inside: np.ndarray, outside: np.ndarray, radius: float) -> float:
        """β in [0, 1] with ‖D^½ (a + β (b − a))‖ = Δ, for a inside the region and b outside."""
        between = outside - inside
        a = float(between @ (self._scale * between))
        b = 2.0 * float(inside @ (self._scale * between))
        c = float(inside @ (self._scale * inside)) - radius * radius
        return (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)

    def update(self, accepted: bool, decrease: float, proposal: _Proposal) -> None:
        rho = decrease / proposal.predicted if accepted and proposal.predicted > 0 else 0.0
        if rho > 0.75:
            self.radius = max(self.radius, 3.0 * self._scaled_norm)
        elif rho < 0.25:
            self.radius = 0.5 * self._scaled_norm

    def rejected(self, graph, system, proposal: _Proposal, trial) -> str | None:
        """Why the run ends after a rejected step, or None to try again."""
        if not (np.isfinite(self.radius) and self.radius > 0.0):
            return "trust region collapsed (no step lowers the error)"
        if self.unmeasured is None and self.options.damping == "diagonal":
            self.unmeasured = _unmeasured_share(graph, system)
            self._stale = bool(self.unmeasured.any())
        return None


_STEPS = {
    "lm": _LevenbergMarquardt,
    "gn": functools.partial(_LevenbergMarquardt, damped=False),
    "dogleg": lambda options, diagonal: _Dogleg(options),
}
"""The step strategy of each ``SolverOptions.method``, from the options and diag(H) at the
start (Levenberg-Marquardt's identity damping scales λ by its largest entry)."""


def _singular_termination(graph: PoseGraph) -> str:
    """Why Gauss-Newton stopped when H did not factorise, naming the nodes with directions that
    no measurement reaches (``posegraph.observability``), if there are any."""
    counts = unmeasured_directions(graph)
    where = f" ({describe_unmeasured(graph, counts)})" if counts.any() else ""
    return (
        f"normal equations singular: some direction is measured by nothing{where};"
        " Gauss-Newton does not damp it, Levenberg-Marquardt does"
    )
