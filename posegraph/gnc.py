"""Graduated non-convexity with a truncated-least-squares kernel (Yang, Antonante, Tzoumas &
Carlone 2020, "Graduated Non-Convexity for Robust Spatial Perception", Alg. 1), then a
consistency pass and a local search.

1. Solve least squares; set μ = c²/(2 s_max − c²), where the surrogate is convex.
2. Repeat: weigh the edges by the TLS-GNC weights of their current residuals, solve the weighted
   problem, raise μ by 1.4; until the weights are binary. Edges of weight 0 are left out of the
   linear system (the random fill-in of false loops would dominate the cost).
   Yang et al. solve every stage globally. Here a stage is solved twice over: warm-started from
   the previous stage, and (SE2, SE3) from the chordal relaxation of the weighted problem; the
   run that ends with the lower TLS objective Σ min(s, c²) is kept.
3. Consistency: restart from the chordal relaxation of the kept (outlier-free) edges, solve least
   squares, keep every edge with s ≤ c² at the solution, and repeat until the kept set no longer
   changes. This re-admits true loops that an early, outlier-distorted stage had pushed out.
4. Local search, in rounds (up to ``LOCAL_SEARCH_ROUNDS``) while a round changes the kept set:
   - re-admit: the rejected loops whose innovation χ² against the solution is below c²
     (``posegraph.leverage.innovations``) and that the other re-admitted loops explain are
     added back together, and the kept set is settled as in step 3 (warm-started). A region
     that drifted while its true loops were rejected fits them badly (large s) but predicts the
     misfit (small innovation), and they pull the region back for each other;
   - drop: for the kept loops with the largest deleted residuals d² (``posegraph.leverage``:
     what leaving the loop out would save, to first order), re-solve without each one
     (warm-started). A false loop that the solution bent itself to fit has a small residual s
     but a large d².
   Each change is kept only if it lowers the TLS objective Σ min(s, c²).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .chordal import supports as supports_chordal
from .factors import between_squares
from .graph import PoseGraph
from .initialization import initialize
from .leverage import Leverage, deleted_residuals
from .lie import LieGroup
from .linear import NormalEquations
from .robust import tls_gnc_weights
from .solvers import Result, SolverOptions
from .solvers import optimize as solve

MU_FACTOR = 1.4
MAX_ROUNDS = 200
MAX_CONSISTENCY_PASSES = 10
LOCAL_SEARCH_CANDIDATES = 5
LOCAL_SEARCH_ROUNDS = 3
EXPLAINED = 0.75
"""Re-admission: the share of a rejected loop's s that the other re-admitted loops must remove.
The others explain none of a lone false loop's s at first order; 56% was seen, from the
nonlinearity (s 4562 without it, against 10307 before, on intel)."""
STAGE_ITERATIONS = 10
STAGE_RELATIVE_DECREASE = 1e-5


@dataclasses.dataclass(frozen=True)
class GncOutcome:
    result: Result
    """The final least-squares solve over the kept edges (its summary counts only that solve)."""
    rejected: np.ndarray
    """Indices of the between edges rejected as outliers."""
    rounds: int
    iterations: int
    """Solver iterations over all stages."""


def _tls_objective(graph: PoseGraph, values: LieGroup, mask: np.ndarray, width_sq: float) -> float:
    """Σ min(s, c²) over the edges in ``mask``, plus Σ s over the others, at ``values``."""
    s = between_squares(values, graph.edges)
    return float(np.where(mask, np.minimum(s, width_sq), s).sum())


def _stages(graph, mask, width_sq, options, start: Result, restart: bool):
    """GNC rounds from the least-squares solution ``start``; returns (result, weights, rounds,
    iterations)."""
    stage = dataclasses.replace(
        options, max_iterations=STAGE_ITERATIONS, relative_decrease=STAGE_RELATIVE_DECREASE
    )
    result, iterations, rounds = start, 0, 0
    s = between_squares(result.values, graph.edges)
    weights = np.ones(graph.num_edges)
    largest = s[mask].max(initial=0.0)
    if largest <= width_sq:
        return result, weights, rounds, iterations
    mu = width_sq / (2.0 * largest - width_sq)
    active, system = None, None
    while rounds < MAX_ROUNDS:
        rounds += 1
        weights[mask] = tls_gnc_weights(s[mask], width_sq, mu)
        now_active = weights > 0
        work = graph.weighted(weights)
        if active is None or not np.array_equal(now_active, active):
            active = now_active
            system = NormalEquations(work, work.gauge_nodes(), options.linear_solver)
        work.set_values(initialize(work, "chordal") if restart else result.values)
        result = solve(work, stage, system=system)
        iterations += result.summary.num_iterations
        s = between_squares(result.values, graph.edges)
        if rounds > 1 and np.all((weights[mask] < 1e-6) | (weights[mask] > 1.0 - 1e-6)):
            break
        mu *= MU_FACTOR
    return result, weights, rounds, iterations


def gnc_tls(
    graph: PoseGraph, mask: np.ndarray, width: float, options: SolverOptions | None = None
) -> GncOutcome:
    """GNC-TLS over the between edges in ``mask`` (the others are trusted), from the graph's
    values; ``width`` c is the largest inlier residual, in Mahalanobis units."""
    options = options or SolverOptions()
    width_sq = width**2
    start = solve(graph, dataclasses.replace(options, relative_decrease=STAGE_RELATIVE_DECREASE))
    iterations, rounds = start.summary.num_iterations, 0
    best, best_objective = None, np.inf
    for restart in (False, True) if supports_chordal(graph.group) else (False,):
        result, weights, stage_rounds, stage_iterations = _stages(
            graph, mask, width_sq, options, start, restart
        )
        rounds, iterations = rounds + stage_rounds, iterations + stage_iterations
        objective = _tls_objective(graph, result.values, mask, width_sq)
        if best is None or objective < best_objective:  # the first, even if not finite
            best, best_objective = (result, weights), objective
    result, weights = best

    kept, result, settle_iterations = _settle(
        graph, mask, ~mask | (weights > 0.5), result.values, width_sq, options, restart=True
    )
    iterations += settle_iterations
    objective = _tls_objective(graph, result.values, mask, width_sq)
    leverage = _leverage(graph, kept, result, options)
    for _ in range(LOCAL_SEARCH_ROUNDS):
        changed = False
        for step in (_readmit, _drop):
            trial_kept, trial, trial_objective, trial_iterations = step(
                graph, mask, kept, result, objective, width_sq, options, leverage
            )
            iterations += trial_iterations
            if trial is not None and trial_objective < objective:
                kept, result, objective, changed = trial_kept, trial, trial_objective, True
                leverage = _leverage(graph, kept, result, options)
        if not changed:
            break
    return GncOutcome(result, np.flatnonzero(~kept), rounds, iterations)


def _leverage(graph, kept, result, options) -> Leverage:
    """The probe estimates at the solution ``result`` over the kept edges (computed on first
    use, then shared by re-admission and dropping while the solution stands)."""
    return Leverage(graph.with_edges(kept), result.values, linear_solver=options.linear_solver)


def _settle(graph, mask, kept, values, width_sq, options, restart: bool):
    """Least squares over the kept edges, then keep every edge with s ≤ c² at the solution;
    repeat until the kept set no longer changes. Returns (kept, result, iterations). With
    ``restart`` (SE2, SE3) the first solve starts from the chordal relaxation of the kept edges,
    which escapes a basin that an early, outlier-distorted GNC stage may have led into."""
    iterations, result = 0, None
    for settle_pass in range(MAX_CONSISTENCY_PASSES):
        work = graph.with_edges(kept)
        if settle_pass == 0 and restart and supports_chordal(graph.group):
            work.set_values(initialize(work, "chordal"))
        else:
            work.set_values(values)
        result = solve(work, options)
        iterations += result.summary.num_iterations
        values = result.values
        consistent = ~mask | (between_squares(values, graph.edges) <= width_sq)
        if np.array_equal(consistent, kept):
            break
        kept = consistent
    return kept, result, iterations


def _readmit(graph, mask, kept, result, objective, width_sq, options, leverage):
    """Re-admit the rejected loops that the other re-admitted loops make consistent, and settle.

    Candidates are the rejected loops whose innovation χ² against the solution is below c² (from
    ``leverage``, the probe estimates at ``result``): adding one alone would lower the TLS
    objective, to first order. A region that drifted while its true loops were rejected fits
    them badly (large s) but predicts the misfit (small innovation). So may a false loop between
    poorly constrained poses, by chance. The candidates are solved for together, and a candidate
    stays one only if the others explain it: its s at the joint solution fitted without it (its
    exact deleted residual) is at most c², or at most ``1 − EXPLAINED`` of its s before. This
    repeats over the remaining candidates until all are explained, then the kept set with them
    is settled. The loops of a drifted region pull it back for each other; a lone false loop is
    consistent only with the solution bent to fit it, and without it, its misfit is what it was.
    Returns (kept, result or None, its TLS objective, iterations)."""
    rejected = np.flatnonzero(mask & ~kept)
    if rejected.size == 0:
        return kept, None, objective, 0
    innovation = leverage.innovations(graph.edges.subset(rejected))
    candidates = rejected[innovation < width_sq]
    misfit = between_squares(result.values, graph.edges)
    values, iterations = result.values, 0
    for _ in range(MAX_CONSISTENCY_PASSES):
        if candidates.size == 0:
            break
        with_candidates = kept.copy()
        with_candidates[candidates] = True
        work = graph.with_edges(with_candidates)
        work.set_values(values)
        joint = solve(work, options)
        values, iterations = joint.values, iterations + joint.summary.num_iterations
        position = np.cumsum(with_candidates) - 1  # of each edge in ``work``
        squares = deleted_residuals(
            work, values, edges=position[candidates], linear_solver=options.linear_solver
        ).squares
        explained = (squares <= width_sq) | (squares <= (1.0 - EXPLAINED) * misfit[candidates])
        if explained.all():
            kept, settled, settle_iterations = _settle(
                graph, mask, with_candidates, values, width_sq, options, restart=False
            )
            settled_objective = _tls_objective(graph, settled.values, mask, width_sq)
            return kept, settled, settled_objective, iterations + settle_iterations
        candidates = candidates[explained]
    return kept, None, objective, iterations


def _drop(graph, mask, kept, result, objective, width_sq, options, leverage):
    """Leave out, one at a time, the kept loops of largest deleted residual d² (from
    ``leverage``, the probe estimates at ``result``), keeping each removal that lowers the TLS
    ``objective`` of ``result``. Returns (kept, result or None, its TLS objective, iterations)."""
    scores = np.zeros(graph.num_edges)
    scores[kept] = leverage.deleted_residuals().innovation
    # Dropping a loop lowers the objective when d² > c²; below c²/2 the estimate's error
    # (≈ 30%) cannot hide such a loop.
    candidates = np.flatnonzero(mask & kept & (scores > 0.5 * width_sq))
    best, iterations = None, 0
    for edge in candidates[np.argsort(-scores[candidates])][:LOCAL_SEARCH_CANDIDATES]:
        without = kept.copy()
        without[edge] = False
        work = graph.with_edges(without)
        work.set_values(result.values)
        trial = solve(work, options)
        iterations += trial.summary.num_iterations
        trial_objective = _tls_objective(graph, trial.values, mask, width_sq)
        if trial_objective < objective:
            kept, result, objective, best = without, trial, trial_objective, trial
    return kept, best, objective, iterations
