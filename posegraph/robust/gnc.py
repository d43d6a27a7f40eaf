"""Graduated non-convexity with a truncated-least-squares kernel (Yang, Antonante, Tzoumas &
Carlone 2020, "Graduated Non-Convexity for Robust Spatial Perception", Alg. 1), then a
consistency pass and a local search.

1. Solve least squares (``START_ITERATIONS`` at most); set μ = min c²/(2s − c²) over the edges
   with s > c² (c²/(2 s_max − c²) for one width), where the surrogate is convex.
2. Repeat: weigh the edges by the TLS-GNC weights of their current residuals, solve the weighted
   problem, raise μ by 1.4; until the weights are binary. Edges of weight 0 are left out of the
   linear system (the random fill-in of false loops would dominate the cost).
   Yang et al. solve every stage globally. Here a stage whose support (the edges of weight
   > 0) changed starts from the chordal relaxation of the weighted problem, which does not
   depend on where the last stage stopped; a stage over the last one's support, whose weights
   moved only within it, starts where that stage stopped.
3. Consistency: from the chordal relaxation of the kept (outlier-free) edges, solve least
   squares as ``optimize`` would (a fresh start, with the caller's options), keep every edge
   with s ≤ c² at the solution, and repeat until the kept set no longer changes. This re-admits
   true loops that an early, outlier-distorted stage had pushed out. The same from the values
   the stages left; the lower TLS objective is kept.
4. Local search (``local_search``), in rounds (up to ``LOCAL_SEARCH_ROUNDS``) while a round changes the kept set:
   - re-admit: the rejected loops whose innovation χ² against the solution is below c²
     (``posegraph.robust.leverage.innovations``), or that together have a joint innovation below
     their Σ c², and that the other re-admitted loops explain, are added back together, and
     the kept set is settled as in step 3, from both starts. A region that drifted while its
     true loops were rejected fits them badly (large s) but predicts the misfit (small
     innovation), and they pull the region back for each other;
   - drop: for the kept loops with the largest deleted residuals d² (``posegraph.robust.leverage``:
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

import numpy as np

from ..graph import PoseGraph
from ..init.choice import initialize
from ..problem.factors import between_squares
from ..solvers import (
    Callback,
    Result,
    SolverOptions,
)
from .kernels import tls_gnc_weights
from .local_search import local_search
from .tls import INITIAL_DAMPING, Run, Stopped, settle_best, tls_objective

MU_FACTOR = 1.4
MAX_ROUNDS = 200
DECISION_SOLVES = 2
"""Least-squares solves that a call's previous decisions get to settle in: the decisions with
the new measurements kept, then once more without what misfits there (``_settle_decisions``);
settling them fully costs as much as GNC's stages where every step brings a false loop."""
STAGE_ITERATIONS = 5
"""Most Levenberg-Marquardt iterations of a graduated stage's solve from its chordal
relaxation: the next stage, a little less convex, weighs the edges where it stops."""
STAGE_RELATIVE_DECREASE = 1e-5
START_ITERATIONS = 20
"""Most Levenberg-Marquardt iterations of least squares over every edge, GNC's start: with
false loops its minimum is no estimate, only where μ starts, and Levenberg-Marquardt crawls
towards it."""


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


def _stages(graph, mask, width_sq, options, start: Result, run: Run):
    """GNC rounds from the least-squares solution ``start``, each solved from the chordal
    relaxation of its weighted problem, or from the last round's solution where the support is
    that round's; returns (result, weights)."""
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
    active = None
    while rounds < MAX_ROUNDS:
        rounds += 1
        run.rounds += 1
        weights[mask] = tls_gnc_weights(s[mask], width_sq[mask], mu)
        now_active = weights > 0
        work = graph.weighted(weights)
        if active is None or not np.array_equal(now_active, active):
            active = now_active
            work.set_values(initialize(work, "chordal"), check=False)
            label = f"gnc round {rounds} (chordal)"
        else:
            work.set_values(result.values, check=False)
            label = f"gnc round {rounds} (warm)"
        result = run.solve(work, stage_options, label)  # over one support: one system
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
    graduate: bool = True,
    search: bool = True,
) -> GncOutcome:
    """GNC-TLS over the between edges in ``mask`` (the others trusted), from the graph's
    values; ``width`` c, the largest inlier residual in Mahalanobis units, is one or per edge.

    ``callback`` receives every iteration of every solve (``IterationRecord.stage`` says which).
    When it returns True, or when ``options.time_limit`` has passed since the run began, the
    run stops after that iteration, with the values reached and the edges of the mask with
    s > c² there rejected (termination ``STOPPED`` or ``TIME_LIMIT``).

    ``options.max_iterations`` caps every solve (GNC's stages at ``STAGE_ITERATIONS``). With
    0, nothing is searched: the values stand, and the edges of the mask with s > c² at them are
    rejected, as when the run is stopped.

    ``kept``, decisions known to stand (``smoother.warm_start``), skips the search: the kept
    edges are solved for in least squares, and the others are rejected. ``start``, decisions
    that may still hold (an earlier run's, with what was added since kept), replaces steps 1–3
    if least squares over them settles as it is, and competes with them otherwise
    (``_settle_decisions``); the local search follows. Without ``search``, only steps 1–2 and
    5 run (GNC anew at a width that calibration may change again). Without ``graduate``, steps
    1–3 never run: ``start`` is settled as in step 3 (``settle_best``) and searched from there,
    as calibration's re-solves do (``robust.calibration``)."""
    options = options or SolverOptions()
    search_options = options
    if options.initial_damping is None:
        search_options = dataclasses.replace(options, initial_damping=INITIAL_DAMPING)
    width_sq = np.broadcast_to(np.square(width, dtype=float), graph.num_edges)
    run = Run(callback, options)
    from_start = False
    initial_error = 0.5 * tls_objective(graph, graph.values, mask, width_sq)
    try:
        if kept is None and options.max_iterations == 0:  # no solve moves: the values stand
            result = run.solve(graph, options, "least squares")
            kept = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
        elif kept is None:
            kept, searched, from_start, leverage = _search(
                graph, mask, width_sq, search_options, run, start, graduate, search
            )
            result = _final(graph.with_edges(kept), searched, leverage, options, run)
        else:
            result = run.solve(graph.with_edges(kept), options, "carried decisions")
    except Stopped as stopped:
        result = stopped.result
        kept = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
    final_error = 0.5 * tls_objective(graph, result.values, mask, width_sq)
    summary = run.summary(result.summary, initial_error, final_error)
    return GncOutcome(
        dataclasses.replace(result, summary=summary), np.flatnonzero(~kept), run.rounds, from_start
    )


def _final(work: PoseGraph, searched: Result, leverage, options, run: Run) -> Result:
    """GNC's step 5: least squares over the kept edges (``work``) from the search's solution,
    carrying the search's ``leverage`` where the solution stayed where it computed them."""
    work.set_values(searched.values, check=False)
    result = run.solve(work, options, "final")
    if leverage is not None and leverage.serves(work, result.values):
        result = dataclasses.replace(result, leverage=leverage)
    return result


def _search(
    graph, mask, width_sq, options, run: Run, start=None, graduate: bool = True, search=True
):
    """GNC's steps 1–4 (module docstring); returns (kept edges, the final solve, whether it
    began at ``start``, the local search's leverages at its solution or None). ``start``, the
    kept edges of an earlier run extended by what was appended since, replaces steps 1–3 where
    least squares over it settles as it is, and competes with them where it settles only after
    a change (``_settle_decisions``); without ``graduate``, it is settled as step 3 settles
    GNC's decisions, and steps 1–3 never run. Without ``search``, steps 3–4 do not run after
    steps 1–2."""
    if start is not None and not graduate:
        settled = settle_best(graph, mask, start, graph.values, width_sq, options, run)
        kept, result, leverage = local_search(graph, mask, *settled, width_sq, options, run)
        return kept, result, True, leverage
    settled, as_given = (
        (None, False)
        if start is None
        else _settle_decisions(graph, mask, start, width_sq, options, run)
    )
    from_start = settled is not None
    if not as_given:
        graduated = _graduated(graph, mask, width_sq, options, run, settle=search)
        if settled is None or graduated[2] <= settled[2]:
            settled, from_start = graduated, False
    if not search:
        return settled[0], settled[1], from_start, None
    kept, result, leverage = local_search(graph, mask, *settled, width_sq, options, run)
    return kept, result, from_start, leverage


def _graduated(
    graph, mask, width_sq, options, run: Run, settle: bool = True
) -> tuple[np.ndarray, Result, float]:
    """GNC's steps 1–3 from the graph's values (without ``settle``, 1–2): (kept edges, their
    solve, its TLS objective)."""
    least_squares = dataclasses.replace(
        options,
        max_iterations=min(options.max_iterations, START_ITERATIONS),
        relative_decrease=STAGE_RELATIVE_DECREASE,
    )
    start = run.solve(graph, least_squares, "least squares")
    result, weights = _stages(graph, mask, width_sq, options, start, run)
    kept = ~mask | (weights > 0.5)
    if not settle:
        return kept, result, tls_objective(graph, result.values, mask, width_sq)
    return settle_best(graph, mask, kept, result.values, width_sq, options, run)


def _settle_decisions(graph, mask, kept, width_sq, options, run: Run):
    """Least squares over the ``kept`` edges from the graph's values, until a solution keeps
    every kept edge of the mask within its width and leaves every other outside (a fixed point
    of step 3), in at most ``DECISION_SOLVES`` solves: each next one over the edges that the
    last solution kept so, from there. Returns ((kept, result, TLS objective), whether the
    first solve settled), or (None, False) where none settled."""
    values = graph.values
    for solves in range(DECISION_SOLVES):
        work = graph.with_edges(kept)
        work.set_values(values, check=False)
        result = run.solve(work, options, "previous decisions")
        consistent = ~mask | (between_squares(result.values, graph.edges) <= width_sq)
        if np.array_equal(consistent, kept):
            return (kept, result, tls_objective(graph, result.values, mask, width_sq)), solves == 0
        kept, values = consistent, result.values
    return None, False
