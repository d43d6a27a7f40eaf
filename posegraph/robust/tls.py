"""The truncated least-squares (TLS) problem that GNC and its local search solve: its objective,
their solves run as one run, and the settling of a kept set (Yang et al. 2020, eq. 2)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..graph import PoseGraph
from ..init.choice import initialize
from ..lie import LieGroup
from ..problem.factors import between_squares, prior_squares
from ..problem.linear import NormalEquations
from ..solvers import (
    STOPPED,
    TIME_LIMIT,
    Callback,
    IterationRecord,
    Result,
    SolverOptions,
    Summary,
    solve,
)

MAX_CONSISTENCY_PASSES = 10
INITIAL_DAMPING = 1e-10
"""Levenberg-Marquardt's initial λ in GNC's solves unless the options set one, but for the
fresh starts from a chordal relaxation, which take least squares' (``DEFAULT_INITIAL_DAMPING``):
GNC's decisions depend on where its stages' few iterations end, and its search was validated
with this value (``docs/architecture.md``)."""


class Stopped(Exception):
    """The caller's callback asked to stop, or the run's time limit passed; carries the solve
    that this ended."""

    def __init__(self, result: Result) -> None:
        super().__init__(result.summary.termination)
        self.result = result


class Run:
    """GNC's solves as one run, as the caller sees it: their iterations numbered in turn, timed
    from the run's start and labelled by stage, their phase times summed. The options' time
    limit is the run's. When the callback asks to stop or the time is up, the solve under way
    ends and ``Stopped`` carries it out. ``options`` are the caller's, which solves from a
    fresh start use (``settle``). A solve over the same structure as the last one (the same
    edges' ends, priors and held nodes: GNC's rounds over one support, a settling pass that
    kept what it was given, the final solve after the search) reuses its normal equations:
    their pattern and CHOLMOD's symbolic analysis."""

    def __init__(self, callback: Callback | None, options: SolverOptions) -> None:
        self.callback = callback
        self.options = options
        self.start = time.perf_counter()
        self.history: list[IterationRecord] = []
        self.phase_times: dict[str, float] = {}
        self.rounds = 0
        self._last_system: NormalEquations | None = None

    def solve(self, graph: PoseGraph, options: SolverOptions, stage: str) -> Result:
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
        last = self._last_system
        shared = last is not None and last.describes(graph, graph.gauge_nodes())
        result = solve(graph, options, report, system=last if shared else None)
        if shared:  # within one call: nothing a warm start reused (``Summary.reused``)
            result = dataclasses.replace(
                result, summary=dataclasses.replace(result.summary, reused=())
            )
        self._last_system = result.system
        for phase, seconds in result.summary.phase_times.items():
            self.phase_times[phase] = self.phase_times.get(phase, 0.0) + seconds
        if result.summary.termination in (STOPPED, TIME_LIMIT):
            raise Stopped(result)
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


def settle(graph, mask, kept, values, width_sq, options, run: Run, restart: bool):
    """Least squares over the kept edges, then keep every edge with s ≤ c² at the solution;
    repeat until the kept set no longer changes. Returns (kept, result). With ``restart`` the
    first solve starts from the chordal relaxation of the kept edges, which escapes a basin
    that an early, outlier-distorted GNC stage may have led into. That solve is a fresh start,
    made with the caller's options (``run.options``): least squares' initial λ unless they set
    one, not ``INITIAL_DAMPING``."""
    result = None
    for settle_pass in range(MAX_CONSISTENCY_PASSES):
        work = graph.with_edges(kept)
        if settle_pass == 0 and restart:
            work.set_values(initialize(work, "chordal"), check=False)
            result = run.solve(work, run.options, "consistency (chordal)")
        else:
            work.set_values(values, check=False)
            result = run.solve(work, options, "consistency")
        values = result.values
        consistent = ~mask | (between_squares(values, graph.edges) <= width_sq)
        if np.array_equal(consistent, kept):
            break
        kept = consistent
    return kept, result


def settle_best(graph, mask, kept, values, width_sq, options, run: Run):
    """``settle`` from ``values`` and from the chordal relaxation of the kept edges; the lower
    TLS objective wins, and within the solves' tolerance (``relative_decrease``) the chordal
    one, which does not depend on where earlier solves stopped. Returns (kept, result, its TLS
    objective). Loops re-admitted together can pull a region out of the basin that the values
    lie in; from chordal, a graph can also settle in a worse basin than the values lie in."""
    best = None
    for restart in (False, True):
        settled_kept, settled = settle(graph, mask, kept, values, width_sq, options, run, restart)
        objective = tls_objective(graph, settled.values, mask, width_sq)
        if best is None or objective <= best[2] * (1.0 + options.relative_decrease):
            best = settled_kept, settled, objective
    return best
