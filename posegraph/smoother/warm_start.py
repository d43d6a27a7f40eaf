"""The warm-start policy of a ``Smoother``: start from the last solution, compose what was added,
restart where the new measurements disagree, skip the solve where the solution extends or
where what was added could lower the optimum by little (``SolverOptions.skip_within``), and
carry GNC's decisions where the graph has only grown."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph, measured_dof
from ..init.choice import choose, initialize
from ..problem.backends import resolve_backend
from ..robust.kernels import default_width
from ..robust.spec import Kernel
from ..solvers import PHASES, Result, SolverOptions, Summary
from .composition import compose_new_nodes, initialize_new_nodes
from .growth import Growth
from .solution import Solution

WARM_START_QUANTILE = 0.999
"""A warm start restarts from chordal when its new measurements' Σ rᵀΩr exceeds χ²_m(0.999)."""
COMPOSED = (
    "the new nodes hang off the previous solution by a tree of edges: composed, already optimal"
)
"""The termination of a warm start that ``solution_extends``: no iterations were needed."""
RESTART = "chordal (restart: the new measurements disagree with the previous solution)"
"""The initialisation of a warm start that failed ``_agree_with_solution``."""
SKIPPED = "skipped: the measurements added since the last solve lower the optimum by little"
"""The termination of a call that ``skipped_debt`` let skip its solve."""


@dataclasses.dataclass(frozen=True)
class Start:
    """How a call starts: the initialisation's name, what it reused, GNC's carried decisions,
    and, where the call solves nothing, how much the start's cost may exceed the optimum's
    (``Solution.debt``): the solution's, where it extends to the grown graph, or more, where
    the call skips its solve (``skipped_debt``), with the error ½ Σ rᵀΩr of the measurements
    added since at the start (``added_error``)."""

    init: str
    reused: tuple[str, ...] = ()
    standing: np.ndarray | None = None
    decisions: np.ndarray | None = None
    graduate: bool = True
    search: bool = True
    debt: float | None = None
    added_error: float = 0.0


def warm_started(
    graph: PoseGraph, solution: Solution, kernel: Kernel | None, options: SolverOptions
) -> Start:
    """The start of a call on a smoother that solved before: the graph's values from its last
    ``solution`` (``warm_start``, or composed where it extends), GNC's carried decisions, and
    whether the call may solve nothing (``Start.debt``)."""
    solved = int(graph.initialized.sum())
    growth = Growth(graph, solution)
    decisions = standing = None
    if kernel is not None and kernel.spec.gnc:
        decisions = previous_decisions(growth, kernel)
    if decisions is not None and standing_decisions(growth, kernel.measured):
        standing = decisions
    same_problem = standing is not None if kernel else solution.summary.robust is None
    debt, added_error = None, 0.0  # a tree's edges fit its composed nodes exactly
    if same_problem and solution_extends(growth):
        solved = len(solution.fixed)
        compose_new_nodes(graph, np.arange(graph.num_nodes) >= solved)
        init = "warm start"
        debt = affordable(solution.debt, solution.summary.final_error, options)
    else:
        init = warm_start(graph, growth, options, least_squares=kernel is None)
        if kernel is None and init == "warm start":
            debt = skipped_debt(growth, options)
            if debt is not None:
                added_error = 0.5 * growth.added_chi2
    reused = (f"previous solution ({solved} nodes)",) if init == "warm start" else ()
    if standing is not None:
        reused += (
            f"GNC's decisions ({np.count_nonzero(~standing)} rejected; nothing added since"
            " is under the kernel)",
        )
    return Start(init, reused, standing, decisions, debt=debt, added_error=added_error)


def warm_start(
    graph: PoseGraph, growth: Growth, options: SolverOptions, least_squares: bool
) -> str:
    """Start from the previous solution, composing and refining the nodes added since
    (``composition.initialize_new_nodes``); returns the initialisation's name.

    A local start can sit in the wrong basin once new loop closures pull the map far (a noisy
    graph). In least squares, when the new measurements fail ``_agree_with_solution`` on a
    graph with loops, the values restart from chordal relaxation, as a new graph's would.
    """
    if not graph.initialized.all():
        initialize_new_nodes(graph, options)
    if least_squares and not _agree_with_solution(growth) and choose(graph) == "chordal":
        graph.set_values(initialize(graph, "chordal"), check=False)
        return RESTART
    return "warm start"


def previous_decisions(growth: Growth, kernel: Kernel) -> np.ndarray | None:
    """The last GNC run's decisions, carried to the robust problem (``_robust_problem``) of the
    grown graph: the edges (and priors, where the problem holds them) that the run kept, and
    every measurement appended since. None unless that run solved the same problem to its end
    (the same kernel and width, and ``kernel``'s robust class the same over its measurements)
    and the graph has only grown since: its measurements come first and unchanged (those that
    remain, after ``PoseGraph``'s removals: ``Solution.without``)."""
    graph, solution = growth.graph, growth.solution
    if solution.gnc is None or not solution.gnc.spec.same_kernel(kernel.spec):
        return None
    measured, measured_then = kernel.measured, solution.gnc.measured
    old_edges, old_priors = len(solution.edges), len(solution.priors)
    with_priors, then_with_priors = len(measured) > graph.num_edges, len(measured_then) > old_edges
    if with_priors != then_with_priors and old_priors > 0:
        return None  # the priors joined or left the robust problem
    old = np.arange(old_edges)
    if then_with_priors:
        old = np.concatenate([old, graph.num_edges + np.arange(old_priors)])
    if not (growth.measurements_kept and np.array_equal(measured[old], measured_then)):
        return None
    kept = np.ones(len(measured), dtype=bool)
    kept[:old_edges] = solution.edge_weights > 0
    if with_priors:
        kept[graph.num_edges : graph.num_edges + old_priors] = solution.prior_weights > 0
    return kept


def standing_decisions(growth: Growth, measured: np.ndarray) -> bool:
    """Whether the last GNC run's ``decisions`` (``previous_decisions``) stand for the grown
    graph: all that was added since is a tree of trusted between edges that hangs free new
    nodes off the solved ones, nothing in ``measured``, no prior, no hold, no cycle. The TLS
    problem over the solved nodes is then unchanged, and each new node has one place that fits
    its edges exactly, so the decisions are as good for the grown graph as they were for the
    old one, and a least-squares solve over them ends it."""
    return not measured[len(growth.solution.edges) : growth.graph.num_edges].any() and growth.tree


def solution_extends(growth: Growth) -> bool:
    """Whether the last solution, with the new nodes composed along the new edges, is an
    optimum of the graph, given that the problem over the solved nodes is the one it solved
    (least squares again, or GNC's decisions standing: the caller checks): its solve converged,
    the solved nodes still hold its values, and the graph grew by a tree (``Growth.tree``) of
    edges whose information is full rank. The new edges' residuals are then zero and the rest
    of the cost is at its optimum, so no solve can lower it."""
    return (
        growth.solution.summary.converged
        and growth.tree
        and growth.values_kept
        and bool(np.all(growth.new_ranks == growth.graph.group.dof))
    )


def skipped_debt(growth: Growth, options: SolverOptions) -> float | None:
    """How much the cost at the warm start (the solved nodes at their values, the new ones
    refined) may exceed the grown graph's optimum, where that is at most
    ``options.skip_within`` of the cost, so that the call may skip its solve; else None.

    Where the solved nodes hold values whose cost exceeds the optimum of the measurements they
    were solved for by at most the solution's ``debt`` (0 at a converged solve), the grown
    graph's optimum is at least that optimum (each measurement's cost is ≥ 0), and the cost at
    the warm start is that cost plus the added measurements' cost c: the excess is at most
    ``debt`` + c. Only where the graph grew by appended nodes and edges alone
    (``Growth.appended``: a new prior may free a held node)."""
    solution = growth.solution
    if not (
        options.skip_within > 0
        and solution.summary.converged
        and growth.appended
        and growth.values_kept
    ):
        return None
    added = 0.5 * growth.added_chi2
    return affordable(solution.debt + added, solution.summary.final_error + added, options)


def affordable(debt: float, cost: float, options: SolverOptions) -> float | None:
    """``debt``, where a call may leave it unsolved: none, or at most ``options.skip_within``
    of the ``cost``; else None."""
    return debt if debt == 0 or debt <= options.skip_within * cost else None


def composed_result(
    graph: PoseGraph, solution: Solution, options: SolverOptions, start: Start
) -> Result:
    """The graph's values as a result of no iterations: an optimum by ``solution_extends``, or
    within the ``start``'s debt of one where the call skipped its solve (``skipped_debt``). Its
    error is the solution's plus that of the measurements added since (``Start.added_error``),
    and the free nodes are the solution's and the new ones (neither adds a hold)."""
    previous, debt = solution.summary, start.debt
    error = previous.final_error + start.added_error
    new_nodes = graph.num_nodes - len(solution.fixed)
    summary = Summary(
        method=options.method,
        linear_solver=resolve_backend(options.linear_solver),
        initial_error=error,
        final_error=error,
        iterations=[],
        termination=COMPOSED if debt == 0 else f"{SKIPPED} (at most {debt:.3g})",
        converged=True,
        phase_times=dict.fromkeys(PHASES, 0.0),
        total_time=0.0,
        num_variables=previous.num_variables + new_nodes * graph.group.dof,
    )
    return Result(graph.values, summary)


def _agree_with_solution(growth: Growth) -> bool:
    """Whether the measurements added since the last solution are consistent with it, by a χ²
    innovation test: their Σ rᵀΩr at the warm start is below χ²_m(``WARM_START_QUANTILE``),
    m = Σ rank Ω, the directions they measure (the solved nodes keep their values, so the cost
    of the others is unchanged). Only appended measurements are tested: if some were removed
    or changed since, this holds, as the solution still suits the measurements that remain."""
    if not growth.measurements_kept:
        return True
    dof = int(growth.new_ranks.sum()) + measured_dof(growth.new_priors.information)
    if dof == 0:
        return True
    return growth.added_chi2 <= default_width(dof, WARM_START_QUANTILE) ** 2
