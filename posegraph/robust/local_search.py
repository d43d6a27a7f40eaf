"""GNC's local search (step 4 of ``gnc``): re-admit rejected loops that the others explain, and
drop kept loops that the solution bent itself to fit, each change kept only if it lowers the
TLS objective."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..problem.cholesky import NotPositiveDefinite
from ..problem.factors import between_squares
from .leverage import Leverage, deleted_residuals
from .tls import MAX_CONSISTENCY_PASSES, Run, settle_best, tls_objective

LOCAL_SEARCH_CANDIDATES = 5
LOCAL_SEARCH_ROUNDS = 3
JOINT_POOL = 32
"""Re-admission weighs together at most this many rejected loops, those of smallest
innovation (``_jointly_consistent``)."""
JOINT_ITERATIONS = 20
"""Most iterations of a joint solve of more than ``JOINT_POOL`` re-admitted loops: those that
fit together converge in a few (2 on manhattan), those that crumple the map do not converge in
100 (w10000 and parking-garage: ``docs/architecture.md``)."""
EXPLAINED = 0.75
"""Re-admission: the share of a rejected loop's s that the other re-admitted loops must remove.
The others explain none of a lone false loop's s at first order, but some through the
nonlinearity, so the share is well above one half."""
NEAR = 2.0
"""Re-admission: a candidate whose s at the solution is at most this many times its width c²
needs no other loop to explain it. Loops just outside the width may fit only together, each
pulling the other in too little to count as explained; a loop this close bends the solution
little even if it is false (``docs/architecture.md``)."""


def local_search(graph, mask, kept, result, objective, width_sq, options, run: Run):
    """GNC's step 4 from the kept edges and their solve; returns (kept edges, their solve, the
    leverages at its solution)."""
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
                return kept, result, None
            if trial is not None and trial_objective < objective:
                kept, result, objective, changed = trial_kept, trial, trial_objective, True
                leverage = _leverage(graph, kept, result, options)
        if not changed:
            break
    return kept, result, leverage


def _leverage(graph, kept, result, options) -> Leverage:
    """The deleted residuals and innovations at the solution ``result`` over the kept edges
    (computed on first use, then shared by re-admission and dropping while the solution
    stands)."""
    return Leverage(
        graph.with_edges(kept), result.values, linear_solver=options.linear_solver, solved=result
    )


def _readmit(graph, mask, kept, result, objective, width_sq, options, leverage, run: Run):
    """Re-admit the rejected loops that the other re-admitted loops make consistent, and settle.

    Candidates are the rejected loops whose innovation χ² against the solution is below c² (from
    ``leverage`` at ``result``, exact for up to 256/d loops): adding one alone would lower the
    TLS objective, to first order. A region that drifted while its true loops were rejected fits
    them badly (large s) but predicts the misfit (small innovation). So may a false loop between
    poorly constrained poses, by chance. Loops that only together would lower it are candidates
    too (``_jointly_consistent``). The candidates are solved for together, and a candidate stays
    one only if the others explain it: its s at the joint solution fitted without it (its exact
    deleted residual) is at most c², or at most ``1 − EXPLAINED`` of its s before, or its s
    before is within ``NEAR`` c². This repeats over the remaining candidates until all are
    explained, then the kept set with them is settled. The loops of a drifted region pull it
    back for each other; a lone false loop is consistent only with the solution bent to fit
    it, and without it, its misfit is what it was. More candidates than ``JOINT_POOL`` whose
    joint solve does not converge within ``JOINT_ITERATIONS`` do not fit together (hundreds of
    false loops, each consistent alone, crumpling the map): nothing is re-admitted. (A few
    true loops of a monocular sequence's drifted scale can take more iterations than a solve
    has.)
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
        work.set_values(values, check=False)
        many = candidates.size > JOINT_POOL
        readmitted = run.solve(work, _joint_options(options) if many else options, "re-admit")
        if many and not readmitted.summary.converged:
            break
        values = readmitted.values
        position = np.cumsum(with_candidates) - 1  # of each edge in ``work``
        squares = deleted_residuals(
            work, values, edges=position[candidates], linear_solver=options.linear_solver
        ).squares
        explained = (
            (squares <= width_sq[candidates])
            | (squares <= (1.0 - EXPLAINED) * misfit[candidates])
            | (misfit[candidates] <= NEAR * width_sq[candidates])
        )
        if explained.all():
            return settle_best(graph, mask, with_candidates, values, width_sq, options, run)
        candidates = candidates[explained]
    return kept, None, objective


def _joint_options(options):
    """``options`` with at most ``JOINT_ITERATIONS`` iterations."""
    return dataclasses.replace(
        options, max_iterations=min(options.max_iterations, JOINT_ITERATIONS)
    )


def _jointly_consistent(graph, rejected, innovation, width_sq, leverage: Leverage) -> np.ndarray:
    """The rejected loops that added together would lower the TLS objective, to first order: of
    the ``JOINT_POOL`` of smallest ``innovation`` (exact or estimated), in that order, the
    leading ones whose exact joint innovation is furthest below their Σ c²; none if no leading
    set is below. The true loops of a region that drifted far can each disagree with the
    solution by about c² or more and agree with each other."""
    finite = np.isfinite(innovation)
    order = np.argsort(innovation[finite])[:JOINT_POOL]
    pool = rejected[finite][order]
    if np.all(innovation[finite][order] < width_sq[pool]):  # each passes alone already
        return pool[:0]
    increments = leverage.sequential_innovations(graph.edges.subset(pool))
    gain = np.cumsum(width_sq[pool] - increments)
    best = int(np.argmax(gain))
    return pool[: best + 1] if gain[best] > 0 else pool[:0]


def _drop(graph, mask, kept, result, objective, width_sq, options, leverage, run: Run):
    """Leave out, one at a time, the kept loops of largest deleted residual d² (from
    ``leverage`` at ``result``), keeping each removal that lowers the TLS ``objective`` of
    ``result``. Returns (kept, result or None, its TLS objective)."""
    deleted = leverage.deleted_residuals
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
        work.set_values(result.values, check=False)
        trial = run.solve(work, options, "drop")
        trial_objective = tls_objective(graph, trial.values, mask, width_sq)
        if trial_objective < objective:
            kept, result, objective, best = without, trial, trial_objective, trial
    return kept, best, objective
