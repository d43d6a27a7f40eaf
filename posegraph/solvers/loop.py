"""Gauss-Newton, Levenberg-Marquardt and Powell's dogleg over the fixed-pattern normal equations.

One loop serves all three; each method proposes steps (``steps``).
Each iteration tries X ⊕ δ (right retraction on every free node) and accepts the step only if
the error is finite and lower. Levenberg-Marquardt's step solves (H + λD) δ = −g, with λ = 0
for Gauss-Newton, and updates λ by the gain ratio
ρ = (actual decrease) / (predicted decrease ½ δᵀ(λDδ − g)): on success
λ ← λ·max(1/3, 1 − (2ρ − 1)³) and ν ← 2; on failure λ ← λ·ν and ν ← 2ν
(Nielsen 1999; Madsen, Nielsen & Tingleff 2004, §3.2).
A rejected step costs a refactorisation and an evaluation of the residuals: the Jacobians
are computed only at accepted values, and the linearisation is kept. The dogleg's rejected
step costs the evaluation alone: its trust region shrinks about the same factorisation.
After an accepted Gauss-Newton step, the factorisation that gave it is asked first: its Newton
decrement ends the run, or its chord step finishes it, without factorising anew
(``_after_newton_step``).

Marquardt's D = diag(H) scales the damping with the curvature. A direction that no measurement
reaches at first order (``posegraph.problem.observability``: the rotation of a pose seen only by
position-only edges) still has a little curvature where residuals are not zero, through the
Log's coupling, so its damped steps are huge and rejected one after another, and
Levenberg-Marquardt crawls. From the first rejected step on, those directions
are damped by λ max diag(H), as identity damping (gtsam's and g2o's default) would.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

import numpy as np

from ..graph import PoseGraph
from ..problem.linear import NormalEquations
from ..problem.linearization import EdgeWeighting, Linearized
from .options import SolverOptions
from .steps import STEPS, Proposal, inner
from .summary import PHASES, IterationRecord, Result, Summary

Callback = Callable[[IterationRecord], bool | None]
"""Called after every iteration; returning True stops the run (termination ``STOPPED``)."""
STOPPED = "stopped by callback"
TIME_LIMIT = "time limit reached"
MAX_ITERATIONS = "maximum iterations reached"
PREDICTED_BELOW_TOLERANCE = "predicted error decrease below tolerance"
STEP_BELOW_TOLERANCE = "step below tolerance"
GRADIENT_BELOW_TOLERANCE = "gradient below tolerance"
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


def solve(
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
    system, reused = _normal_equations(graph, options, system, previous)
    clock.lap("other")
    last = None if previous is None else previous.linearization
    current = Linearized(graph, graph.values, weighting, last)
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
        reused=tuple(reused),
    )
    return Result(current.values, summary, system, current)


def _normal_equations(
    graph: PoseGraph,
    options: SolverOptions,
    system: NormalEquations | None,
    previous: Result | None,
) -> tuple[NormalEquations, list[str]]:
    """``system`` if given, else new normal equations (grown from ``previous``'s pattern where
    the graph grew by appending); and what was reused, as ``Summary.reused`` names it."""
    if system is not None:
        return system, ["sparsity pattern", "symbolic factorization"]
    grow_from = None if previous is None else previous.system
    system = NormalEquations(graph, graph.gauge_nodes(), options.linear_solver, previous=grow_from)
    return system, ["sparsity pattern (grown)"] if system.grown else []


class _Assembled:
    """The gradient at a linearisation (its Jacobians timed as linearisation), and H's CSC data
    (kept as ``current.normal_matrix``) and diagonal there, assembled on first use: a run that
    ends on the gradient's Newton decrement (``_after_newton_step``) never needs them."""

    def __init__(self, system: NormalEquations, current: Linearized, clock: _Clock) -> None:
        _ = current.between  # the Jacobians, cached: timed as linearisation
        clock.lap("linearize")
        self.gradient = current.gradient_in(system)
        clock.lap("assemble")
        self._system, self._current, self._clock = system, current, clock

    @functools.cached_property
    def data(self) -> np.ndarray:
        self._clock.lap("linearize")
        data = self._current.normal_matrix_in(self._system)
        self._clock.lap("assemble")
        return data

    @functools.cached_property
    def diagonal(self) -> np.ndarray:
        return self._system.diagonal(self.data)

    def for_step(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(H's data, the gradient, diag(H)): what a step is proposed from."""
        return self.data, self.gradient, self.diagonal


def _iterate(graph, options, callback, system, weighting, clock, current, history):
    """The iterations of ``solve``; returns (final linearisation, termination, converged).
    ``history`` receives a record per iteration."""
    termination, converged = MAX_ITERATIONS, False
    assembled = _Assembled(system, current, clock)
    steps = STEPS[options.method](options, assembled.diagonal)
    fresh = True  # a linearisation not yet proposed from
    chord = None  # the next step, from the last factorisation (``_after_newton_step``)
    # |x| of the step test, at the start: it changes little over a run, and a Log of every
    # node per iteration would cost as much as a linearisation on small graphs.
    size = _norm(current.values.log())

    for iteration in range(1, options.max_iterations + 1):
        stop = _stop_before_step(options, assembled.gradient, clock)
        if stop is not None:
            termination, converged = stop
            break
        proposal, stale, chord = chord, chord is not None, None
        if not stale:
            proposal = steps.propose(graph, system, *assembled.for_step(), fresh, clock)
            fresh = False
        if _promises_little(options, proposal, current.error):
            termination, converged = PREDICTED_BELOW_TOLERANCE, True
            break
        trial = _trial(graph, system, weighting, current, proposal, clock)
        step_norm = _norm(proposal.step)
        accepted = bool(
            trial is not None and np.isfinite(trial.error) and trial.error < current.error
        )
        decrease = current.error - trial.error if accepted else 0.0
        if not stale:
            steps.update(accepted, decrease, proposal)
        previous_error = current.error
        if accepted:
            current = trial
        record = IterationRecord(
            iteration, current.error, steps.damping, step_norm, accepted, clock.elapsed()
        )
        history.append(record)
        if callback is not None and callback(record):
            termination = STOPPED
            break
        small = step_norm < options.step_tolerance * (size + options.step_tolerance)
        if accepted:
            stop = _stop_after_acceptance(options, steps, proposal, decrease, previous_error, small)
        elif not stale:  # after a rejected chord step, the linearisation is factorised
            stop = _stop_after_rejection(graph, system, steps, proposal, trial, small)
        if stop is not None:
            termination, converged = stop
            break
        if not accepted:
            continue
        assembled = _Assembled(system, current, clock)
        fresh = True
        if proposal.newton:
            done, chord = _after_newton_step(options, system, assembled, current, decrease, clock)
            if done:
                termination, converged = PREDICTED_BELOW_TOLERANCE, True
                break
    return current, termination, converged


def _norm(array: np.ndarray) -> float:
    """The Euclidean norm of all the entries (``steps.inner``, not BLAS)."""
    flat = array.ravel()
    return float(np.sqrt(inner(flat, flat)))


def _stop_before_step(options: SolverOptions, gradient: np.ndarray, clock: _Clock):
    """(termination, converged) where the run ends before proposing a step, else None."""
    if np.max(np.abs(gradient)) < options.gradient_tolerance:
        return GRADIENT_BELOW_TOLERANCE, True
    if options.time_limit is not None and clock.elapsed() > options.time_limit:
        return TIME_LIMIT, False
    return None


def _trial(graph, system, weighting, current, proposal, clock) -> Linearized | None:
    """The linearisation at the proposed values, or None where there is no step. A step far
    beyond the quadratic model's reach (along a direction measured only weakly) can overflow, as
    a Sim3 scale of e^800: its error is then not finite, and the step is rejected."""
    if not proposal.ok:
        return None
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        trial_values = current.values.retract(system.scatter(proposal.step))
        trial = Linearized(graph, trial_values, weighting)
    clock.lap("linearize")
    return trial


def _stop_after_rejection(graph, system, steps, proposal, trial, small: bool):
    """(termination, converged) where a rejected step ends the run, else None. A step that
    changes the values only at rounding level and still does not lower the error finds the
    error at its floating-point floor (a map in UTM coordinates, whose residuals cannot fall
    below about 1e-9 m), as Ceres's parameter tolerance does."""
    if proposal.ok and small:
        return STEP_BELOW_TOLERANCE, True
    stop = steps.rejected(graph, system, proposal, trial)
    return None if stop is None else (stop, False)


def _stop_after_acceptance(options, steps, proposal, decrease, previous_error, small: bool):
    """(termination, converged) where an accepted step ends the run, else None."""
    tolerance = options.relative_decrease * previous_error
    if decrease <= tolerance and (not steps.damped or proposal.predicted <= tolerance):
        return "relative error decrease below tolerance", True
    if small:
        return STEP_BELOW_TOLERANCE, True
    return None


CHORD_MARGIN = 1e-3
"""A chord step is taken where it is predicted to leave a Newton decrement below this share of
the tolerance (``_after_newton_step``): as little as a Newton step would leave, not a linearly
converging tail just under the tolerance."""


def _after_newton_step(
    options, system, assembled: _Assembled, current, decrease, clock
) -> tuple[bool, Proposal | None]:
    """After an accepted (near) Gauss-Newton step, what the factorisation just used says at the
    new values, where H has changed by second order: (converged, next step), from the gradient
    there (``assembled``, whose H is assembled only if a later step needs it). The run has
    converged where the Newton decrement p = ½ gᵀH⁻¹g promises less than the tolerance t,
    without a new factorisation. Near the optimum the decrement shrinks by q = p / (the step's
    decrease) per step; where q·p ≤ ``CHORD_MARGIN``·t, δ = −H⁻¹g is the last step (the chord,
    or simplified Newton, method: Kelley 2003, "Solving Nonlinear Equations with Newton's
    Method", §2.3.3), at the cost of a solve, not of a factorisation."""
    gradient = assembled.gradient
    step = -system.solve(gradient)
    clock.lap("solve")
    chord = Proposal(step, -0.5 * inner(gradient, step), True, False, True)
    tolerance = options.relative_decrease * current.error
    if _promises_little(options, chord, current.error):
        return True, None
    if 0 < chord.predicted**2 <= CHORD_MARGIN * tolerance * decrease and np.all(np.isfinite(step)):
        return False, chord
    return False, None


def _promises_little(options: SolverOptions, proposal: Proposal, error: float) -> bool:
    """Whether a (near) Gauss-Newton step's quadratic model promises less than the tolerance:
    the run has converged, without spending a linearisation on evaluating the step."""
    return (
        proposal.ok
        and proposal.newton
        and 0 <= proposal.predicted <= options.relative_decrease * error
    )
