"""One robust solve of a graph under a resolved kernel (``spec.Kernel``): the robust problem (the
priors as edges where the kernel covers them), its cost, and the summary's record of what was
rejected."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..graph import PoseGraph
from ..problem.factors import between_squares, chi2, prior_squares
from ..solvers import Callback, Result, SolverOptions, Summary, solve
from .anchoring import priors_as_edges
from .gnc import gnc_tls, tls_objective
from .kernels import Robustifier, RobustKernel
from .spec import Kernel

DECISIONS_AS_START = "with the new measurements kept, as the search's start"
"""How ``summary.reused`` names GNC's previous decisions when its search started from them."""

WarmSolve = Callable[[PoseGraph, SolverOptions, Callback | None, Robustifier | None], Result]
"""A least-squares or IRLS solve of the graph that reuses what the caller kept (``Smoother``)."""


@dataclasses.dataclass(frozen=True)
class RobustOutcome:
    """A robust solve's result (its summary records the kernel and the rejections), and the
    weights of the between edges and of the priors at its solution (0 where rejected)."""

    result: Result
    edge_weights: np.ndarray
    prior_weights: np.ndarray


def robust_problem(graph: PoseGraph, kernel: Kernel) -> PoseGraph:
    """The graph as the robust solvers see it: where the kernel covers the priors, they become
    edges from a held world node (``priors_as_edges``)."""
    return graph if len(kernel.measured) == graph.num_edges else priors_as_edges(graph)


def cost(graph: PoseGraph, kernel: Kernel | None) -> float:
    """The cost that a solve minimises, at the graph's values: ½ Σ rᵀΩr in least squares
    (``kernel`` None); else ½ Σ ρ(s) over the robust class and ½ Σ s over the rest, with
    ρ(s) = min(s, c²) for GNC (truncated least squares) or the kernel's ρ."""
    if kernel is None:
        return 0.5 * chi2(graph.values, graph.edges, graph.priors)
    work = robust_problem(graph, kernel)
    if kernel.spec.gnc:
        return 0.5 * tls_objective(work, work.values, kernel.measured, kernel.widths**2)
    costs, _ = _weighting(kernel).cost_and_weights(between_squares(work.values, work.edges))
    return 0.5 * float(costs.sum() + prior_squares(work.values, work.priors).sum())


def _weighting(kernel: Kernel) -> Robustifier:
    return Robustifier(RobustKernel(kernel.name, kernel.widths[kernel.measured]), kernel.measured)


def robust_solve(
    graph: PoseGraph,
    kernel: Kernel,
    options: SolverOptions,
    callback: Callback | None,
    warm_solve: WarmSolve,
    standing: np.ndarray | None = None,
    decisions: np.ndarray | None = None,
    graduate: bool = True,
    search: bool = True,
) -> RobustOutcome:
    """A robust solve from the graph's values. ``standing``, GNC's decisions that stand (the
    measurements to keep), skips GNC's search; ``decisions``, the last GNC run's carried to this
    graph, may start it (``summary.reused`` says so), and without ``graduate`` only settle and
    search from there (``gnc.gnc_tls``: decisions of the same call, which calibration passes on);
    without ``search``, GNC does not search locally. An IRLS kernel over the between edges alone
    solves through ``warm_solve``."""
    work = robust_problem(graph, kernel)
    reused: tuple[str, ...] = ()
    if kernel.spec.gnc:
        outcome = gnc_tls(
            work,
            kernel.measured,
            kernel.widths,
            options,
            callback,
            kept=standing,
            start=decisions,
            graduate=graduate,
            search=search,
        )
        result, rejected = outcome.result, outcome.rejected
        if outcome.from_start and graduate:
            rejected_then = np.count_nonzero(~decisions)
            reused = (f"GNC's decisions ({rejected_then} rejected), {DECISIONS_AS_START}",)
        weights = np.ones(work.num_edges)
        weights[rejected] = 0.0
    else:
        weighting = _weighting(kernel)
        if work is graph:
            result = warm_solve(graph, options, callback, weighting)
        else:  # a new graph at every call
            result = solve(work, options, callback, weighting=weighting)
        s = between_squares(result.values, work.edges)
        rejected = np.flatnonzero(kernel.measured & (s > kernel.widths**2))
        _, weights = weighting.cost_and_weights(s)
    anchored = work is not graph
    values = result.values[: graph.num_nodes] if anchored else result.values
    summary = dataclasses.replace(result.summary, reused=result.summary.reused + reused)
    result = dataclasses.replace(
        result, values=values, summary=with_robust_record(summary, kernel, rejected, graph)
    )
    if anchored:  # the world node is last; the system and linearisation are work's
        result = Result(result.values, result.summary)
    count = graph.num_edges
    prior_weights = weights[count:] if anchored else np.ones(len(graph.priors))
    return RobustOutcome(result, weights[:count], prior_weights)


def with_robust_record(
    summary: Summary, kernel: Kernel, rejected: np.ndarray, graph: PoseGraph
) -> Summary:
    """``summary`` with the kernel, the rejected measurements (``rejected``, indices over the
    robust problem's edges: the between edges, then the priors where the kernel covers them)
    and how many of each the kernel covered."""
    count = graph.num_edges
    return dataclasses.replace(
        summary,
        robust=kernel.label,
        rejected_edges=rejected[rejected < count].tolist(),
        rejected_priors=(rejected[rejected >= count] - count).tolist(),
        edges_under_kernel=int(kernel.measured[:count].sum()),
        priors_under_kernel=int(kernel.measured[count:].sum()),
    )
