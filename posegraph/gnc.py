"""Graduated non-convexity with a truncated-least-squares kernel (Yang, Antonante, Tzoumas &
Carlone 2020, "Graduated Non-Convexity for Robust Spatial Perception", Alg. 1), then a
consistency pass and a local search.

1. Solve least squares; set μ = min c²/(2s − c²) over the edges with s > c² (c²/(2 s_max − c²)
   for one width), where the surrogate is convex.
2. Repeat: weigh the edges by the TLS-GNC weights of their current residuals, solve the weighted
   problem, raise μ by 1.4; until the weights are binary. Edges of weight 0 are left out of the
   linear system (the random fill-in of false loops would dominate the cost).
   Yang et al. solve every stage globally. Here a stage is solved twice over: warm-started from
   the previous stage, and (SE2, SE3, Sim3) from the chordal relaxation of the weighted
   problem; the run that ends with the lower TLS objective Σ min(s, c²) is kept.
3. Consistency: from the chordal relaxation of the kept (outlier-free) edges, solve least
   squares as ``optimize`` would (a fresh start, with the caller's options), keep every edge
   with s ≤ c² at the solution, and repeat until the kept set no longer changes. This re-admits
   true loops that an early, outlier-distorted stage had pushed out. The same from the values
   the stages left; the lower TLS objective is kept.
4. Local search, in rounds (up to ``LOCAL_SEARCH_ROUNDS``) while a round changes the kept set:
   - re-admit: the rejected loops whose innovation χ² against the solution is below c²
     (``posegraph.leverage.innovations``), or that together have a joint innovation below
     their Σ c², and that the other re-admitted loops explain, are added back together, and
     the kept set is settled as in step 3, from both starts. A region that drifted while its
     true loops were rejected fits them badly (large s) but predicts the misfit (small
     innovation), and they pull the region back for each other;
   - drop: for the kept loops with the largest deleted residuals d² (``posegraph.leverage``:
     what leaving the loop out would save, to first order), re-solve without each one
     (warm-started). A false loop that the solution bent itself to fit has a small residual s
     but a large d².
   Each change is kept only if it lowers the TLS objective Σ min(s, c²).
5. The kept edges are solved for in least squares from there, with the caller's options: the
   steps above start Levenberg-Marquardt's λ at ``INITIAL_DAMPING`` unless the options set it,
   but for the fresh starts of step 3.

A call may bring decisions that may still hold (``start``: an earlier run's, on a graph that
has grown since, with the new measurements kept). Least squares over them replaces steps 1–3
if its solution keeps every kept edge within its width and leaves every rejected one outside
(a fixed point of step 3); the local search then judges them as it judges GNC's. Where they do
not settle so (a new false loop that misfits, or an old rejected loop that now fits), least
squares runs once more over the edges that solution keeps within their widths, steps 1–3 run
as on a new graph, and the search goes on from the lower TLS objective of the two (from GNC's,
if that second solve does not settle either).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .chordal import supports as supports_chordal
from .factors import between_squares, prior_squares
from .graph import PoseGraph
from .initialization import initialize
from .leverage import Leverage, deleted_residuals
from .lie import LieGroup
from .linear import NormalEquations
from .robust import tls_gnc_weights
from .solvers import (
    STOPPED,
    TIME_LIMIT,
    Callback,
    IterationRecord,
    Result,
    SolverOptions,
    Summary,
)
from .solvers import optimize as solve
from .sparse_cholesky import NotPositiveDefinite

MU_FACTOR = 1.4
MAX_ROUNDS = 200
MAX_CONSISTENCY_PASSES = 10
LOCAL_SEARCH_CANDIDATES = 5
LOCAL_SEARCH_ROUNDS = 3
DECISION_SOLVES = 2
"""Least-squares solves that a call's previous decisions get to settle in: the decisions with
the new measurements kept, then once more without what misfits there (``_settle_decisions``).
Settling them fully took as long as GNC's stages on streams whose every step brings a false
loop (manhattan in steps of 100 poses: 1.3× the time of calls from scratch), and GNC's stages
won each time there."""
JOINT_POOL = 32
"""Re-admission weighs together at most this many rejected loops, those of smallest
innovation (``_jointly_consistent``)."""
EXPLAINED = 0.75
"""Re-admission: the share of a rejected loop's s that the other re-admitted loops must remove.
The others explain none of a lone false loop's s at first order; 56% was seen, from the
nonlinearity (s 4562 without it, against 10307 before, on intel)."""
STAGE_ITERATIONS = 10
STAGE_RELATIVE_DECREASE = 1e-5
INITIAL_DAMPING = 1e-10
"""Levenberg-Marquardt's initial λ in GNC's solves, unless the options set one, but for the
consistency pass's solve from the chordal relaxation of the kept edges: a fresh start, which
takes least squares' λ (``solvers.options.DEFAULT_INITIAL_DAMPING``, 1e-12). GNC's decisions
depend on where its stages' few iterations end, and the search was validated with this value:
with 1e-12 throughout, six of its scenario tests took other paths (a fitted false loop kept,
true loops of a drifted region or of a monocular sequence rejected). The fresh start with
1e-10, on monocular sequences at 2.4–2.5% drift with every false loop rejected, led
Levenberg-Marquardt into a valley that it crawled along for 100 iterations (1e-12: 11), and
GNC ended in another basin, at 5.0–7.1 m ATE against the 1.8–2.2 m of least squares without
the false loops."""


@dataclasses.dataclass(frozen=True)
class GncOutcome:
    result: Result
    """The final least-squares solve over the kept edges, with the whole run's summary:
    every solve's iterations (``IterationRecord.stage`` names the stage) and phase times, and
    the TLS cost ½ Σ min(s, c²) (½ s outside the mask, and for priors) as the initial and final
    error."""
    rejected: np.ndarray
    """Indices of the between edges rejected as outliers."""
    rounds: int
    from_start: bool = False
    """Whether the search began at the caller's ``start`` decisions, settled
    (``_settle_decisions``), instead of at GNC's stages."""


class _Stopped(Exception):
    """The caller's callback asked to stop, or the run's time limit passed; carries the solve
    that this ended."""

    def __init__(self, result: Result) -> None:
        super().__init__(result.summary.termination)
        self.result = result


class _Run:
    """GNC's solves as one run, as the caller sees it: their iterations numbered in turn, timed
    from the run's start and labelled by stage, their phase times summed. The options' time
    limit is the run's. When the callback asks to stop or the time is up, the solve under way
    ends and ``_Stopped`` carries it out. ``options`` are the caller's, which solves from a
    fresh start use (``_settle``)."""

    def __init__(self, callback: Callback | None, options: SolverOptions) -> None:
        self.callback = callback
        self.options = options
        self.start = time.perf_counter()
        self.history: list[IterationRecord] = []
        self.phase_times: dict[str, float] = {}
        self.rounds = 0

    def solve(self, graph: PoseGraph, options: SolverOptions, stage: str, system=None) -> Result:
        def report(record: IterationRecord) -> bool:
            record = dataclasses.replace(
                record,
                iteration=len(self.history) + 1,
                elapsed=time.perf_counter() - self.start,
                stage=stage,
            )
            self.history.append(record)
            return self.callback is not None and bool(self.callback(record))

        if options.time_limit is not None:
            left = max(options.time_limit - (time.perf_counter() - self.start), 0.0)
            options = dataclasses.replace(options, time_limit=left)
        result = solve(graph, options, report, system=system)
        for phase, seconds in result.summary.phase_times.items():
            self.phase_times[phase] = self.phase_times.get(phase, 0.0) + seconds
        if result.summary.termination in (STOPPED, TIME_LIMIT):
            raise _Stopped(result)
        return result

    def summary(self, final: Summary, initial_error: float, final_error: float) -> Summary:
        """``final`` (the last solve's summary) widened to the whole run; "other" is the time
        outside the solves' linearisation, assembly, factorisation and solving."""
        total = time.perf_counter() - self.start
        times = {phase: t for phase, t in self.phase_times.items() if phase != "other"}
        times["other"] = total - sum(times.values())
        return dataclasses.replace(
            final,
            initial_error=initial_error,
            final_error=final_error,
            iterations=self.history,
            phase_times=times,
            total_time=total,
        )


def tls_objective(
    graph: PoseGraph, values: LieGroup, mask: np.ndarray, width_sq: float | np.ndarray
) -> float:
    """Σ min(s, c²) over the between edges in ``mask``, plus Σ s over the other edges and the
    priors, at ``values``: twice the cost that GNC-TLS minimises. ``width_sq`` c² is one for
    every edge or one per edge."""
    s = between_squares(values, graph.edges)
    truncated = np.where(mask, np.minimum(s, width_sq), s).sum()
    return float(truncated + prior_squares(values, graph.priors).sum())


def _stages(graph, mask, width_sq, options, start: Result, restart: bool, run: _Run):
    """GNC rounds from the least-squares solution ``start``; returns (result, weights)."""
    stage_options = dataclasses.replace(
        options,
        max_iterations=min(options.max_iterations, STAGE_ITERATIONS),
        relative_decrease=STAGE_RELATIVE_DECREASE,
    )
    result, rounds = start, 0
    s = between_squares(result.values, graph.edges)
    weights = np.ones(graph.num_edges)
    over = mask & (s > width_sq)
    if not over.any():
        return result, weights
    mu = np.min(width_sq[over] / (2.0 * s[over] - width_sq[over]))
    active, system = None, None
    while rounds < MAX_ROUNDS:
        rounds += 1
        run.rounds += 1
        weights[mask] = tls_gnc_weights(s[mask], width_sq[mask], mu)
        now_active = weights > 0
        work = graph.weighted(weights)
        if active is None or not np.array_equal(now_active, active):
            active = now_active
            system = NormalEquations(work, work.gauge_nodes(), options.linear_solver)
        work.set_values(initialize(work, "chordal") if restart else result.values)
        label = f"gnc round {rounds} ({'chordal' if restart else 'warm'})"
        result = run.solve(work, stage_options, label, system=system)
        s = between_squares(result.values, graph.edges)
        if rounds > 1 and np.all((weights[mask] < 1e-6) | (weights[mask] > 1.0 - 1e-6)):
            break
        mu *= MU_FACTOR
    return result, weights


def gnc_tls(
    graph: PoseGraph,
    mask: np.ndarray,
    width: float | np.ndarray,
    options: SolverOptions | None = None,
    callback: Callback | None = None,
    kept: np.ndarray | None = None,
    start: np.ndarray | None = None,
) -> GncOutcome:
    """GNC-TLS over the between edges in ``mask`` (the others are trusted), from the graph's
    values; ``width`` c is the largest inlier residual, in Mahalanobis units: one for every
    edge, or one per edge (n,).

    ``callback`` receives every iteration of every solve (``IterationRecord.stage`` says which).
    When it returns True, or when ``options.time_limit`` has passed since the run began, the
    run stops after that iteration, with the values reached and the edges of the mask with
    s > c² there rejected (termination ``STOPPED`` or ``TIME_LIMIT``).

    ``options.max_iterations`` caps every solve (GNC's stages at ``STAGE_ITERATIONS``). With
    0, nothing is searched: the values stand, and the edges of the mask with s > c² at them are
    rejected, as when the run is stopped.

    ``kept``, decisions known to stand (the edges to keep, ``posegraph.api``), skips the search:
    the kept edges are solved for in least squares, and the others are rejected. ``start``,
    decisions that may still hold (an earlier run's, with what was added since kept), replaces
    steps 1–3 if least squares over them settles as it is, and competes with them otherwise
    (``_settle_decisions``); the local search follows either way."""
    options = options or SolverOptions()
    search = options
    if options.initial_damping is None:
        search = dataclasses.replace(options, initial_damping=INITIAL_DAMPING)
    width_sq = np.broadcast_to(np.square(width, dtype=float), graph.num_edges)
    run = _Run(callback, options)
    from_start = False
    initial_error = 0.5 * tls_objective(graph, graph.values, mask, width_sq)
    try:
        if kept is None and options.max_iterations == 0:  # no solve moves: the values stand
            result = run.solve(graph, options, "least squares")
            kept = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
        elif kept is None:
            kept, searched, from_start = _search(graph, mask, width_sq, search, run, start)
            work = graph.with_edges(kept)
            work.set_values(searched.values)
            result = run.solve(work, options, "final")
        else:
            result = run.solve(graph.with_edges(kept), options, "carried decisions")
    except _Stopped as stopped:
        result = stopped.result
        kept = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
    final_error = 0.5 * tls_objective(graph, result.values, mask, width_sq)
    summary = run.summary(result.summary, initial_error, final_error)
    return GncOutcome(
        dataclasses.replace(result, summary=summary), np.flatnonzero(~kept), run.rounds, from_start
    )


def _search(graph, mask, width_sq, options, run: _Run, start=None):
    """GNC's steps 1–4 (module docstring); returns (kept edges, the final solve, whether it
    began at ``start``). ``start``, the kept edges of an earlier run extended by what was
    appended since, replaces steps 1–3 where least squares over it settles as it is, and
    competes with them where it settles only after a change (``_settle_decisions``)."""
    settled, as_given = (
        (None, False)
        if start is None
        else _settle_decisions(graph, mask, start, width_sq, options, run)
    )
    from_start = settled is not None
    if not as_given:
        graduated = _graduated(graph, mask, width_sq, options, run)
        if settled is None or graduated[2] <= settled[2]:
            settled, from_start = graduated, False
    kept, result = _local_search(graph, mask, *settled, width_sq, options, run)
    return kept, result, from_start


def _graduated(graph, mask, width_sq, options, run: _Run) -> tuple[np.ndarray, Result, float]:
    """GNC's steps 1–3 from the graph's values: (kept edges, their solve, its TLS objective)."""
    least_squares = dataclasses.replace(options, relative_decrease=STAGE_RELATIVE_DECREASE)
    start = run.solve(graph, least_squares, "least squares")
    best, best_objective = None, np.inf
    for restart in _starts(graph):
        result, weights = _stages(graph, mask, width_sq, options, start, restart, run)
        objective = tls_objective(graph, result.values, mask, width_sq)
        if best is None or objective < best_objective:  # the first, even if not finite
            best, best_objective = (result, weights), objective
    result, weights = best
    return _settle_best(graph, mask, ~mask | (weights > 0.5), result.values, width_sq, options, run)


def _settle_decisions(graph, mask, kept, width_sq, options, run: _Run):
    """Least squares over the ``kept`` edges from the graph's values, until a solution keeps
    every kept edge of the mask within its width and leaves every other outside (a fixed point
    of step 3), in at most ``DECISION_SOLVES`` solves: each next one over the edges that the
    last solution kept so, from there. Returns ((kept, result, TLS objective), whether the
    first solve settled), or (None, False) where none settled."""
    values = graph.values
    for solves in range(DECISION_SOLVES):
        work = graph.with_edges(kept)
        work.set_values(values)
        result = run.solve(work, options, "previous decisions")
        consistent = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
        if np.array_equal(consistent, kept):
            return (kept, result, tls_objective(graph, result.values, mask, width_sq)), solves == 0
        kept, values = consistent, result.values
    return None, False


def _local_search(graph, mask, kept, result, objective, width_sq, options, run: _Run):
    """GNC's step 4 from the kept edges and their solve; returns (kept edges, their solve)."""
    leverage = _leverage(graph, kept, result, options)
    for _ in range(LOCAL_SEARCH_ROUNDS):
        changed = False
        for step in (_readmit, _drop):
            try:
                trial_kept, trial, trial_objective = step(
                    graph, mask, kept, result, objective, width_sq, options, leverage, run
                )
            except NotPositiveDefinite:
                # The kept edges' information cannot be factorised even with a ridge (weights
                # of a range beyond double precision): no deleted residual or innovation can
                # be computed, and the search ends at the best solution so far.
                return kept, result
            if trial is not None and trial_objective < objective:
                kept, result, objective, changed = trial_kept, trial, trial_objective, True
                leverage = _leverage(graph, kept, result, options)
        if not changed:
            break
    return kept, result


def _starts(graph: PoseGraph) -> tuple[bool, ...]:
    """The starts a GNC step is solved from: warm (False), and from the chordal relaxation
    (True) where the group has one."""
    return (False, True) if supports_chordal(graph.group) else (False,)


def _leverage(graph, kept, result, options) -> Leverage:
    """The deleted residuals and innovations at the solution ``result`` over the kept edges
    (computed on first use, then shared by re-admission and dropping while the solution
    stands)."""
    return Leverage(graph.with_edges(kept), result.values, linear_solver=options.linear_solver)


def _settle(graph, mask, kept, values, width_sq, options, run: _Run, restart: bool):
    """Least squares over the kept edges, then keep every edge with s ≤ c² at the solution;
    repeat until the kept set no longer changes. Returns (kept, result). With ``restart``
    (SE2, SE3, Sim3) the first solve starts from the chordal relaxation of the kept edges, which
    escapes a basin that an early, outlier-distorted GNC stage may have led into. That solve is
    a fresh start, made with the caller's options (``run.options``): least squares' initial λ
    unless they set one, not ``INITIAL_DAMPING``."""
    result = None
    for settle_pass in range(MAX_CONSISTENCY_PASSES):
        work = graph.with_edges(kept)
        if settle_pass == 0 and restart and supports_chordal(graph.group):
            work.set_values(initialize(work, "chordal"))
            result = run.solve(work, run.options, "consistency (chordal)")
        else:
            work.set_values(values)
            result = run.solve(work, options, "consistency")
        values = result.values
        consistent = ~mask | (between_squares(values, graph.edges) <= width_sq)
        if np.array_equal(consistent, kept):
            break
        kept = consistent
    return kept, result


def _settle_best(graph, mask, kept, values, width_sq, options, run: _Run):
    """``_settle`` from ``values`` and (SE2, SE3, Sim3) from the chordal relaxation of the kept
    edges; the lower TLS objective wins, and within the solves' tolerance
    (``relative_decrease``) the chordal one, which does not depend on where earlier solves
    stopped. Returns (kept, result, its TLS objective). Loops re-admitted together can pull a
    region out of the basin that the values lie in (a monocular sequence with 20 loops back:
    16 m ATE from the values, 1.6 m from chordal); from chordal, a graph can also settle in a
    worse basin than the values lie in (a fuzzed Sim3 graph, with identity damping: a TLS
    objective of 41.7 from chordal, against 7.5 at the start)."""
    best = None
    for restart in _starts(graph):
        settled_kept, settled = _settle(graph, mask, kept, values, width_sq, options, run, restart)
        objective = tls_objective(graph, settled.values, mask, width_sq)
        if best is None or objective <= best[2] * (1.0 + options.relative_decrease):
            best = settled_kept, settled, objective
    return best


def _readmit(graph, mask, kept, result, objective, width_sq, options, leverage, run: _Run):
    """Re-admit the rejected loops that the other re-admitted loops make consistent, and settle.

    Candidates are the rejected loops whose innovation χ² against the solution is below c² (from
    ``leverage`` at ``result``, exact for up to 256/d loops): adding one alone would lower the
    TLS objective, to first order. A region that drifted while its true loops were rejected fits
    them badly (large s) but predicts the misfit (small innovation). So may a false loop between
    poorly constrained poses, by chance. Loops that only together would lower it are candidates
    too (``_jointly_consistent``). The candidates are solved for together, and a candidate stays
    one only if the others explain it: its s at the joint solution fitted without it (its exact
    deleted residual) is at most c², or at most ``1 − EXPLAINED`` of its s before. This repeats
    over the remaining candidates until all are explained, then the kept set with them is
    settled. The loops of a drifted region pull it back for each other; a lone false loop is
    consistent only with the solution bent to fit it, and without it, its misfit is what it was.
    Returns (kept, result or None, its TLS objective)."""
    rejected = np.flatnonzero(mask & ~kept)
    if rejected.size == 0:
        return kept, None, objective
    innovation = leverage.innovations(graph.edges.subset(rejected))
    candidates = np.union1d(
        rejected[innovation < width_sq[rejected]],
        _jointly_consistent(graph, rejected, innovation, width_sq, leverage),
    )
    misfit = between_squares(result.values, graph.edges)
    values = result.values
    for _ in range(MAX_CONSISTENCY_PASSES):
        if candidates.size == 0:
            break
        with_candidates = kept.copy()
        with_candidates[candidates] = True
        work = graph.with_edges(with_candidates)
        work.set_values(values)
        values = run.solve(work, options, "re-admit").values
        position = np.cumsum(with_candidates) - 1  # of each edge in ``work``
        squares = deleted_residuals(
            work, values, edges=position[candidates], linear_solver=options.linear_solver
        ).squares
        explained = (squares <= width_sq[candidates]) | (
            squares <= (1.0 - EXPLAINED) * misfit[candidates]
        )
        if explained.all():
            return _settle_best(graph, mask, with_candidates, values, width_sq, options, run)
        candidates = candidates[explained]
    return kept, None, objective


def _jointly_consistent(graph, rejected, innovation, width_sq, leverage: Leverage) -> np.ndarray:
    """The rejected loops that added together would lower the TLS objective, to first order: of
    the ``JOINT_POOL`` of smallest ``innovation`` (exact or estimated), in that order, the
    leading ones whose exact joint innovation is furthest below their Σ c²; none if no leading
    set is below. The true loops of a region that drifted far can each disagree with the
    solution by about c² or more and agree with each other: at 2% scale drift per keyframe, with
    every loop rejected, 20 true loops of exact innovations 0.9–1.5 c² (estimated 1.2–1.6 c²)
    have a joint innovation of 8.6 c²."""
    finite = np.isfinite(innovation)
    order = np.argsort(innovation[finite])[:JOINT_POOL]
    pool = rejected[finite][order]
    if np.all(innovation[finite][order] < width_sq[pool]):  # each passes alone already
        return pool[:0]
    increments = leverage.sequential_innovations(graph.edges.subset(pool))
    gain = np.cumsum(width_sq[pool] - increments)
    best = int(np.argmax(gain))
    return pool[: best + 1] if gain[best] > 0 else pool[:0]


def _drop(graph, mask, kept, result, objective, width_sq, options, leverage, run: _Run):
    """Leave out, one at a time, the kept loops of largest deleted residual d² (from
    ``leverage`` at ``result``), keeping each removal that lowers the TLS ``objective`` of
    ``result``. Returns (kept, result or None, its TLS objective)."""
    deleted = leverage.deleted_residuals()
    scores = np.zeros(graph.num_edges)
    scores[kept] = deleted.innovation
    # Dropping a loop lowers the objective by d² − min(s', c²) to first order (s' ≥ d², its s
    # at the solution without it), so only where d² > c². Exact d² predicted each trial's
    # change within 0.01 c² (on a 10,000-pose sphere and manhattan, with and without false
    # loops); the probes' estimates (SuperLU) are ≈ 30% off, so they are tried from c²/2.
    least = 1.0 if deleted.exact else 0.5
    candidates = np.flatnonzero(mask & kept & (scores > least * width_sq))
    best = None
    for edge in candidates[np.argsort(-scores[candidates])][:LOCAL_SEARCH_CANDIDATES]:
        without = kept.copy()
        without[edge] = False
        work = graph.with_edges(without)
        work.set_values(result.values)
        trial = run.solve(work, options, "drop")
        trial_objective = tls_objective(graph, trial.values, mask, width_sq)
        if trial_objective < objective:
            kept, result, objective, best = without, trial, trial_objective, trial
    return kept, best, objective
