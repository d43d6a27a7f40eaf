"""The one-call entry point: initialise, then optimise, optionally robustly."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .anchoring import priors_as_edges
from .factors import between_squares, chi2, prior_squares
from .gnc import gnc_tls, tls_objective
from .graph import PoseGraph, Solution, information_ranks, measured_dof, measurement_mask
from .initialization import (
    align_to_priors,
    choose,
    initialize,
    odometry_mask,
    spanning_tree_values,
)
from .robust import KERNELS, Robustifier, RobustKernel, default_width
from .solvers import PHASES, STOPPED, TIME_LIMIT, Callback, Result, SolverOptions, Summary
from .solvers import optimize as solve
from .sparse_cholesky import resolve_backend

ROBUST_EDGE_CLASSES = ("loops", "all")
GNC_NAMES = ("gnc", "tls")
"""Names of graduated non-convexity with the truncated-least-squares kernel in a robust spec."""
LOCAL_RELATIVE_DECREASE = 1e-4
"""Tolerance of the warm start's refinement of new nodes (the full solve follows)."""
LOCAL_MAX_ITERATIONS = 10
"""Most iterations of that refinement: a start, which the full solve finishes."""
GNC_QUANTILE = 0.999
"""Default TLS threshold: an inlier's s = rᵀΩr exceeds √χ²_dof(0.999) once in a thousand."""
WARM_START_QUANTILE = 0.999
"""A warm start restarts from chordal when its new measurements' Σ rᵀΩr exceeds χ²_m(0.999)."""
COMPOSED = (
    "the new nodes hang off the previous solution by a tree of edges: composed, already optimal"
)
"""The termination of a warm start that ``_solution_extends``: no iterations were needed."""
DECISIONS_AS_START = "with the new measurements kept, as the search's start"
"""How ``summary.reused`` names GNC's previous decisions when its search started from them."""
RESTART = "chordal (restart: the new measurements disagree with the previous solution)"
"""The initialisation of a warm start that failed ``_agree_with_solution``."""
KERNEL_QUANTILE = 0.95
"""Default width of the IRLS kernels (Huber, Cauchy, …): √χ²_dof(0.95), Huber's usual choice."""


def robust_mask(graph: PoseGraph, edges: str | np.ndarray) -> np.ndarray:
    """Which between edges a robust kernel applies to: "loops" (not between consecutive nodes),
    "all", or the caller's own class, as a boolean mask over the graph's between edges or as
    their indices (negative ones count from the end). The edges outside it are trusted (gtsam's
    GNC calls them known inliers)."""
    if isinstance(edges, str):
        if edges == "loops":
            return ~odometry_mask(graph)
        if edges == "all":
            return np.ones(graph.num_edges, dtype=bool)
        raise ValueError(
            f"robust edges are {' or '.join(ROBUST_EDGE_CLASSES)}, a boolean mask or edge "
            f"indices, not {edges!r}"
        )
    return measurement_mask(edges, graph.num_edges, "edge", "robust edges")


@dataclasses.dataclass(frozen=True, eq=False)
class _Kernel:
    """A robust spec resolved for one graph (``_robust_kernel``)."""

    name: str
    widths: np.ndarray
    """Each edge's width c, over the robust problem's edges (``_robust_problem``: the between
    edges, then with ``robust_priors`` the priors)."""
    label: str
    """The spec as the summary reports it."""


def _robust_kernel(robust: str, graph: PoseGraph, measured: np.ndarray) -> _Kernel:
    """The kernel of a ``robust`` spec "NAME[:WIDTH]" for ``graph``. Without a width, each
    measurement's is √χ²_k(q) for the k directions its information weighs (its rank: 3 for an
    SE3 position-only fix, not 6), as gtsam's GNC sets one threshold per factor dimension;
    q is ``GNC_QUANTILE`` or ``KERNEL_QUANTILE``. The label gives the width of full-rank
    measurements, and those of other ranks in the robust class ``measured`` (``_robust_class``)."""
    name, _, width_text = robust.partition(":")
    name = name.strip().lower()
    gnc = name in GNC_NAMES
    if not gnc and name not in KERNELS:
        raise ValueError(f"unknown robust kernel {name!r}; choose from gnc, {', '.join(KERNELS)}")
    if width_text:
        try:
            width = float(width_text)
        except ValueError:
            raise ValueError(
                f"a robust kernel's width is a number (as in {name}:2.5), not {width_text!r}"
            ) from None
        if not width > 0:
            raise ValueError(f"a robust kernel's width must be positive, not {width_text}")
        return _Kernel(name, np.full(len(measured), width), f"{name}:{width:.6g}")
    quantile = GNC_QUANTILE if gnc else KERNEL_QUANTILE
    information = graph.edges.information
    if len(measured) > graph.num_edges:  # the priors, as edges
        information = np.concatenate([information, graph.priors.information])
    ranks = information_ranks(information)
    dof = graph.group.dof
    by_rank = np.array([default_width(k, quantile) for k in range(1, dof + 1)])  # rank 1, 2, …
    others = ", ".join(
        f"rank {k}: {by_rank[k - 1]:.6g}" for k in np.unique(ranks[measured]).tolist() if k != dof
    )
    label = f"{name}:{by_rank[-1]:.6g}" + (f" ({others})" if others else "")
    return _Kernel(name, by_rank[ranks - 1], label)


def optimize(
    graph: PoseGraph,
    init: str = "auto",
    options: SolverOptions | None = None,
    callback: Callback | None = None,
    robust: str | None = None,
    robust_edges: str | np.ndarray = "loops",
    robust_priors: bool = False,
) -> Result:
    """Initialise the graph's values by ``init``, minimise its cost, and leave the solution in
    the graph (``graph.values``), so that calling again after adding nodes and edges warm-starts.

    ``init``: see ``posegraph.initialization.initialize``. "auto" warm-starts a graph that was
    optimised before: its nodes keep their values, and nodes added since without values are
    composed from them along a spanning tree and refined alone, the solved nodes held; in least
    squares it restarts from chordal relaxation instead (``RESTART``) when the measurements
    added since disagree with the previous solution (``_warm_start``), and solves nothing
    (``COMPOSED``) when all that was added is new nodes hanging off a converged solution by a
    tree of edges (``_solution_extends``; in GNC, where its decisions stand): composed, they are
    already optimal. On a fresh graph it picks chordal relaxation for graphs with loops, or
    odometry when ``robust`` is set (the odometry chain is trusted). While the structure is
    unchanged, the sparsity pattern and symbolic factorisation of the last call are reused;
    ``summary.reused`` says what was.
    ``robust``: None for least squares; "gnc" for graduated non-convexity with a truncated
    least-squares kernel (``posegraph.gnc``); or a kernel "huber", "cauchy", "geman-mcclure",
    "tukey", "dcs"; each optionally ":WIDTH" in Mahalanobis units (by default, per measurement,
    √χ²_k at ``GNC_QUANTILE`` or ``KERNEL_QUANTILE`` for the k directions it weighs:
    ``_robust_kernel``), applied to ``robust_edges`` ("loops", "all", or a boolean mask over
    the between edges or their indices: ``robust_mask``) and, with ``robust_priors``, to the
    priors too (fixes from GNSS, say; ``posegraph.anchoring``). The summary lists the rejected
    edges and priors (s = rᵀΩr > width²). A GNC call on a graph that has only grown since the
    last one carries that run's decisions (``_previous_decisions``). They stand when all that
    was added is new poses hanging off the map by trusted edges (``_standing_decisions``): the
    call composes the new poses as above, or solves over the decisions where the solution does
    not extend. Otherwise (a new loop, say) least squares over them, with the new measurements
    kept, replaces GNC's stages where it settles as it is, and competes with them where it does
    not (``posegraph.gnc``); the local search follows either way.

    The graph's values are replaced by the initial ones; the result holds the optimum.
    """
    options = options or SolverOptions()
    start = time.perf_counter()
    kernel, measured, gnc_problem, decisions, standing = None, None, None, None, None
    if robust is not None:  # checked before any work is done
        measured = _robust_class(graph, robust_mask(graph, robust_edges), robust_priors)
        kernel = _robust_kernel(robust, graph, measured)
        if kernel.name in GNC_NAMES:
            gnc_problem = (kernel.label, measured)
    input_error = _cost(graph, kernel, measured) if graph.initialized.all() else None
    reused, composed = [], False
    if init == "auto" and graph.optimized:
        solved = int(graph.initialized.sum())
        if gnc_problem is not None:
            decisions = _previous_decisions(graph, kernel.label, measured)
        if decisions is not None and _standing_decisions(graph, decisions, measured):
            standing = decisions
        same_problem = standing is not None if robust else graph.solution.summary.robust is None
        if same_problem and _solution_extends(graph):
            solved = len(graph.solution.fixed)
            _compose_new_nodes(graph, np.arange(graph.num_nodes) >= solved)
            init, composed = "warm start", True
        else:
            init = _warm_start(graph, options, least_squares=robust is None)
        if init == "warm start":
            reused.append(f"previous solution ({solved} nodes)")
        if standing is not None:
            reused.append(
                f"GNC's decisions ({np.count_nonzero(~standing)} rejected; nothing added since"
                " is under the kernel)"
            )
    elif init == "file":
        graph.require_values("add them with values or use init='auto'")
    else:
        if init == "auto":
            init = "odometry" if robust else choose(graph)
        graph.set_values(initialize(graph, init))
    init_time = time.perf_counter() - start

    if composed:
        result = _composed_result(graph, options)
        edge_weights, prior_weights = graph.solution.weights_for(graph.edges, graph.priors)
        if kernel is not None:  # GNC's decisions stand
            _record_robust(result.summary, kernel, measured, np.flatnonzero(~standing), graph)
    elif kernel is None:
        result = _solve_warm(graph, options, callback)
        edge_weights, prior_weights = np.ones(graph.num_edges), np.ones(len(graph.priors))
    else:
        result, edge_weights, prior_weights = _robust_solve(
            graph, kernel, measured, options, callback, standing, decisions
        )
        if result.summary.termination in (STOPPED, TIME_LIMIT) or options.max_iterations == 0:
            gnc_problem = None  # its decisions are not final
    result.summary.initialization = init
    result.summary.initialization_time = init_time
    result.summary.reused = reused + result.summary.reused
    result.summary.input_error = input_error
    result.summary.total_time = time.perf_counter() - start
    graph.set_values(result.values)
    graph.solution = Solution(
        graph.edges,
        graph.priors,
        edge_weights,
        prior_weights,
        graph.fixed.copy(),
        result.values,
        result.summary,
        gnc_problem,
    )
    return result


def _robust_class(graph: PoseGraph, mask: np.ndarray, robust_priors: bool) -> np.ndarray:
    """Which edges of the robust problem (``_robust_problem``) the kernel applies to: ``mask``
    over the between edges, then, with ``robust_priors``, every prior."""
    if not (robust_priors and len(graph.priors) > 0):
        return mask
    return np.concatenate([mask, np.ones(len(graph.priors), dtype=bool)])


def _robust_problem(graph: PoseGraph, measured: np.ndarray) -> PoseGraph:
    """The graph as the robust solvers see it, for the robust class ``measured``
    (``_robust_class``): where that class holds the priors, they become edges from a held
    world node (``priors_as_edges``)."""
    return graph if len(measured) == graph.num_edges else priors_as_edges(graph)


def _cost(graph: PoseGraph, kernel: _Kernel | None, measured: np.ndarray | None) -> float:
    """The cost ``optimize`` minimises, at the graph's values: ½ Σ rᵀΩr in least squares
    (``kernel`` None); else ½ Σ ρ(s) over the robust class and ½ Σ s over the rest, with
    ρ(s) = min(s, c²) for GNC (truncated least squares) or the kernel's ρ."""
    if kernel is None:
        return 0.5 * chi2(graph.values, graph.edges, graph.priors)
    work = _robust_problem(graph, measured)
    if kernel.name in GNC_NAMES:
        return 0.5 * tls_objective(work, work.values, measured, kernel.widths**2)
    weighting = Robustifier(RobustKernel(kernel.name, kernel.widths[measured]), measured)
    costs, _ = weighting.cost_and_weights(between_squares(work.values, work.edges))
    return 0.5 * float(costs.sum() + prior_squares(work.values, work.priors).sum())


def _robust_solve(
    graph: PoseGraph,
    kernel: _Kernel,
    measured: np.ndarray,
    options: SolverOptions,
    callback: Callback | None,
    standing: np.ndarray | None = None,
    decisions: np.ndarray | None = None,
) -> tuple[Result, np.ndarray, np.ndarray]:
    """The robust branch of ``optimize``, from the graph's values: (result, edge weights, prior
    weights), the weights those of the solution (0 where rejected). The summary records the
    kernel and the rejected edges and priors; its errors are the robust cost (``_cost``).
    ``measured`` is the robust class (``_robust_class``); ``standing``, GNC's decisions that
    stand (``_standing_decisions``), if any; ``decisions``, the last GNC run's carried to this
    graph (``_previous_decisions``), if any, which GNC's search may start from."""
    work = _robust_problem(graph, measured)
    if kernel.name in GNC_NAMES:
        outcome = gnc_tls(
            work, measured, kernel.widths, options, callback, kept=standing, start=decisions
        )
        result, rejected = outcome.result, outcome.rejected
        if outcome.from_start:
            result.summary.reused.append(
                f"GNC's decisions ({np.count_nonzero(~decisions)} rejected), {DECISIONS_AS_START}"
            )
        weights = np.ones(work.num_edges)
        weights[rejected] = 0.0
    else:
        weighting = Robustifier(RobustKernel(kernel.name, kernel.widths[measured]), measured)
        if work is graph:
            result = _solve_warm(graph, options, callback, weighting)
        else:  # a new graph at every call
            result = solve(work, options, callback, weighting=weighting)
        s = between_squares(result.values, work.edges)
        rejected = np.flatnonzero(measured & (s > kernel.widths**2))
        _, weights = weighting.cost_and_weights(s)
    anchored = work is not graph
    if anchored:  # the world node is last; the system and linearisation are work's
        result = Result(result.values[: graph.num_nodes], result.summary)
    _record_robust(result.summary, kernel, measured, rejected, graph)
    count = graph.num_edges
    prior_weights = weights[count:] if anchored else np.ones(len(graph.priors))
    return result, weights[:count], prior_weights


def _record_robust(
    summary: Summary, kernel: _Kernel, measured: np.ndarray, rejected: np.ndarray, graph: PoseGraph
) -> None:
    """Record in ``summary`` the kernel, the rejected measurements (``rejected``, indices over
    the robust problem's edges: the between edges, then the priors where ``measured`` holds
    them; ``_robust_class``) and how many of each the kernel covered."""
    count = graph.num_edges
    summary.robust = kernel.label
    summary.rejected_edges = rejected[rejected < count].tolist()
    summary.rejected_priors = (rejected[rejected >= count] - count).tolist()
    summary.edges_under_kernel = int(measured[:count].sum())
    summary.priors_under_kernel = int(measured[count:].sum())


def _warm_start(graph: PoseGraph, options: SolverOptions, least_squares: bool) -> str:
    """Start from the previous solution, composing and refining the nodes added since
    (``_initialize_new_nodes``); returns the initialisation's name.

    A local start can sit in the wrong basin once new loop closures pull the map far (a noisy
    graph). In least squares, when the new measurements fail ``_agree_with_solution`` on a
    graph with loops, the values restart from chordal relaxation, as a new graph's would.
    """
    if not graph.initialized.all():
        _initialize_new_nodes(graph, options)
    if least_squares and choose(graph) == "chordal" and not _agree_with_solution(graph):
        graph.set_values(initialize(graph, "chordal"))
        return RESTART
    return "warm start"


def _previous_decisions(graph: PoseGraph, label: str, measured: np.ndarray) -> np.ndarray | None:
    """The last GNC run's decisions, carried to the robust problem (``_robust_problem``) of the
    grown graph: the edges (and priors, where the problem holds them) that the run kept, and
    every measurement appended since. None unless that run solved the same problem to its end
    (the kernel ``label``, and the robust class ``measured`` the same over its measurements)
    and the graph has only grown since: its measurements come first and unchanged (those that
    remain, after ``PoseGraph``'s removals: ``Solution.without``)."""
    solution = graph.solution
    if solution.gnc is None or solution.gnc[0] != label:
        return None
    measured_then = solution.gnc[1]
    old_edges, old_priors = len(solution.edges), len(solution.priors)
    with_priors, then_with_priors = len(measured) > graph.num_edges, len(measured_then) > old_edges
    if with_priors != then_with_priors and old_priors > 0:
        return None  # the priors joined or left the robust problem
    old = np.arange(old_edges)
    if then_with_priors:
        old = np.concatenate([old, graph.num_edges + np.arange(old_priors)])
    if not (
        graph.edges.starts_with(solution.edges)
        and graph.priors.starts_with(solution.priors)
        and np.array_equal(measured[old], measured_then)
    ):
        return None
    kept = np.ones(len(measured), dtype=bool)
    kept[:old_edges] = solution.edge_weights > 0
    if with_priors:
        kept[graph.num_edges : graph.num_edges + old_priors] = solution.prior_weights > 0
    return kept


def _standing_decisions(graph: PoseGraph, decisions: np.ndarray, measured: np.ndarray) -> bool:
    """Whether the last GNC run's ``decisions`` (``_previous_decisions``) stand for the grown
    graph: all that was added since is a tree of trusted between edges that hangs free new
    nodes off the solved ones, nothing in ``measured``, no prior, no hold, no cycle. The TLS
    problem over the solved nodes is then unchanged, and each new node has one place that fits
    its edges exactly, so the decisions are as good for the grown graph as they were for the
    old one, and a least-squares solve over them ends it."""
    return not measured[len(graph.solution.edges) : graph.num_edges].any() and _grew_by_a_tree(
        graph
    )


def _grew_by_a_tree(graph: PoseGraph) -> bool:
    """Whether all that was added to the graph since its last solution is a tree of between
    edges that hangs the new nodes off the solved ones: the solution is an optimum (nothing
    was removed since: ``Solution.optimal``), its edges and priors come first and unchanged,
    and no prior, no hold and no cycle is new. Each new node then has one place that fits its
    edges exactly, and the problem over the solved nodes is as it was."""
    solution = graph.solution
    old, new_edges = len(solution.fixed), slice(len(solution.edges), None)
    return (
        solution.optimal
        and graph.edges.starts_with(solution.edges)
        and len(graph.priors) == len(solution.priors)
        and graph.priors.starts_with(solution.priors)
        and np.array_equal(graph.fixed[:old], solution.fixed)
        and not graph.fixed[old:].any()
        and _hangs_a_tree(graph.edges.i[new_edges], graph.edges.j[new_edges], old, graph.num_nodes)
    )


def _solution_extends(graph: PoseGraph) -> bool:
    """Whether the last solution, with the new nodes composed along the new edges, is an
    optimum of the graph, given that the problem over the solved nodes is the one it solved
    (least squares again, or GNC's decisions standing: the caller checks): its solve converged,
    the solved nodes still hold its values, and the graph grew by a tree (``_grew_by_a_tree``)
    of edges whose information is full rank. The new edges' residuals are then zero and the
    rest of the cost is at its optimum, so no solve can lower it."""
    solution = graph.solution
    old = len(solution.fixed)
    new_edges = graph.edges.subset(slice(len(solution.edges), None))
    return (
        solution.summary.converged
        and graph.values[:old].same_as(solution.values)
        and _grew_by_a_tree(graph)
        and bool(np.all(information_ranks(new_edges.information) == graph.group.dof))
    )


def _composed_result(graph: PoseGraph, options: SolverOptions) -> Result:
    """The graph's values, an optimum by ``_solution_extends``, as a result of no iterations.
    Its error is the solution's plus that of the new edges (zero, but for rounding), and the
    free nodes are the solution's and the new ones (the tree adds no component and no hold)."""
    previous = graph.solution.summary
    new_edges = graph.edges.subset(slice(len(graph.solution.edges), None))
    error = previous.final_error + 0.5 * float(between_squares(graph.values, new_edges).sum())
    new_nodes = graph.num_nodes - len(graph.solution.fixed)
    summary = Summary(
        method=options.method,
        linear_solver=resolve_backend(options.linear_solver),
        initial_error=error,
        final_error=error,
        iterations=[],
        termination=COMPOSED,
        converged=True,
        phase_times=dict.fromkeys(PHASES, 0.0),
        total_time=0.0,
        num_variables=previous.num_variables + new_nodes * graph.group.dof,
    )
    return Result(graph.values, summary)


def _hangs_a_tree(i: np.ndarray, j: np.ndarray, old: int, count: int) -> bool:
    """Whether edges (i, j) over nodes 0 … count − 1 form a tree over the nodes from ``old`` on
    and the nodes before ``old`` taken as one: one edge per new node, and all connected."""
    new = count - old
    if len(i) != new:
        return False
    # The old nodes become node 0, and new node k becomes k − old + 1.
    ends = np.maximum(np.stack([i, j]) - old + 1, 0)
    adjacency = coo_matrix((np.ones(new), (ends[0], ends[1])), shape=(new + 1, new + 1))
    return connected_components(adjacency, directed=False)[0] == 1


def _agree_with_solution(graph: PoseGraph) -> bool:
    """Whether the measurements added since the last solution are consistent with it, by a χ²
    innovation test: their Σ rᵀΩr at the warm start is below χ²_m(``WARM_START_QUANTILE``),
    m = Σ rank Ω, the directions they measure (the solved nodes keep their values, so the cost
    of the others is unchanged). Only appended measurements are tested: if some were removed
    or changed since, this holds, as the solution still suits the measurements that remain."""
    edges, priors = graph.solution.edges, graph.solution.priors
    if not (graph.edges.starts_with(edges) and graph.priors.starts_with(priors)):
        return True
    new_edges = graph.edges.subset(slice(len(edges), None))
    new_priors = graph.priors.subset(slice(len(priors), None))
    dof = measured_dof(new_edges.information) + measured_dof(new_priors.information)
    if dof == 0:
        return True
    return chi2(graph.values, new_edges, new_priors) <= default_width(dof, WARM_START_QUANTILE) ** 2


def _compose_new_nodes(graph: PoseGraph, new: np.ndarray) -> tuple[PoseGraph, np.ndarray]:
    """Values for the ``new`` nodes (a mask), composed from the others along a spanning tree of
    the edges that touch them (and set in the graph). Returns that local graph, the other nodes
    held, with the new nodes' priors, and which of its nodes are new."""
    touching = new[graph.edges.i] | new[graph.edges.j]
    involved = new.copy()
    involved[graph.edges.i[touching]] = involved[graph.edges.j[touching]] = True
    local = graph.subgraph(involved, edges=touching)
    solved = ~new[involved]
    local.fixed = solved
    local.priors = local.priors.subset(~solved[local.priors.i])
    local.set_values(align_to_priors(local, spanning_tree_values(local, known=solved)))
    graph.set_values(graph.values.set_at(np.flatnonzero(new), local.values[~solved]))
    return local, ~solved


def _initialize_new_nodes(graph: PoseGraph, options: SolverOptions) -> None:
    """Values for nodes added since the last solution: compose them from solved neighbours along
    a spanning tree (``_compose_new_nodes``), then refine them alone (solved nodes held) over
    the edges that touch them, so that the full solve starts close to its optimum."""
    new = ~graph.initialized
    local, local_new = _compose_new_nodes(graph, new)
    local_options = dataclasses.replace(
        options,
        relative_decrease=LOCAL_RELATIVE_DECREASE,
        max_iterations=min(options.max_iterations, LOCAL_MAX_ITERATIONS),
    )
    refined = solve(local, local_options)
    graph.set_values(graph.values.set_at(np.flatnonzero(new), refined.values[local_new]))


def _structure_key(graph: PoseGraph, options: SolverOptions) -> tuple:
    return (graph.structure_version, options.linear_solver)


def _solve_warm(
    graph: PoseGraph,
    options: SolverOptions,
    callback: Callback | None,
    weighting: Robustifier | None = None,
) -> Result:
    """``solve`` on the graph, reusing the last call's normal equations and linearisation where
    they still hold (``_cached_system``), and keeping this call's for the next."""
    system, previous = _cached_system(graph, options)
    result = solve(graph, options, callback, system=system, weighting=weighting, previous=previous)
    graph.last_result = (_structure_key(graph, options), result)
    return result


def _cached_system(graph: PoseGraph, options: SolverOptions):
    """(system, previous result): the last call's normal equations if the graph's structure
    has not changed since (else None, and the solver grows them if the graph only grew), and
    the last call's result (its linearisation is reused where it still holds)."""
    if graph.last_result is None:
        return None, None
    (_, backend), result = graph.last_result
    if backend != options.linear_solver:
        return None, None
    return graph.current_system(options.linear_solver), result
