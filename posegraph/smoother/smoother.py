"""``Smoother``: the back-end object. It owns a pose graph and everything that a later call
reuses: the last solution (warm starts, GNC's decisions, the weights of covariances), and the
normal equations with their sparsity pattern, symbolic factorisation and linearisation."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..graph import PoseGraph, measurement_mask
from ..init.choice import choose, initialize
from ..problem.linear import NormalEquations
from ..robust.calibration import calibrate, kernel_classes
from ..robust.kernels import Robustifier
from ..robust.run import cost, robust_solve, with_robust_record
from ..robust.second_opinion import FromStart
from ..robust.spec import Kernel, RobustSpec, resolve
from ..solvers import STOPPED, TIME_LIMIT, Callback, Result, SolverOptions, solve
from ..solvers.summary import in_turn_summary, named_stages
from . import warm_start
from .fixed_lag import FixedLag
from .solution import GncProblem, Solution
from .warm_start import Start


class Smoother:
    """A pose graph kept optimal across edits, as a SLAM back end calls it after every keyframe::

        smoother = posegraph.Smoother(graph)
        graph.add_node(k); graph.add_edge(k - 1, k, odometry, information)
        result = smoother.optimize()           # warm-starts from the last solution
        covariance = smoother.marginals([k])[0]

    The graph holds data only; the smoother keeps the last ``solution`` and the last solve's
    normal equations, which a later call reuses while the graph's structure allows. Edit the
    graph directly to add; remove through the smoother (``remove_nodes``, ``remove_edges``,
    ``remove_priors``), which carries the last solution's weights and GNC's decisions to the
    measurements that remain.

    With ``lag=K`` it is a fixed-lag smoother (``fixed_lag``): each call optimises the poses
    not yet marginalised, then marginalises all but the newest K (in the graph's order) into a
    Gaussian prior on the poses they reach, as gtsam's ``BatchFixedLagSmoother``; with
    ``lag_seconds=T``, those stamped (``timestamps[node_id] = seconds``) more than T before the
    newest. Marginalised poses keep their last estimate in the graph's values. Such a graph
    only grows, and a new measurement may not reach a marginalised pose."""

    def __init__(
        self, graph: PoseGraph, lag: int | None = None, lag_seconds: float | None = None
    ) -> None:
        self.graph = graph
        fixed = lag is not None or lag_seconds is not None
        self.fixed_lag = FixedLag(lag, lag_seconds) if fixed else None
        """The fixed-lag state (``fixed_lag.FixedLag``), or None for a full smoother."""
        self.solution: Solution | None = None
        """What the last ``optimize`` left in the graph's values (None before the first)."""
        self._last: tuple[tuple[int, str], Result] | None = None
        """The last least-squares or IRLS solve on the graph, keyed by the graph's structure
        version and the linear solver: its normal equations and linearisation."""

    def __getstate__(self) -> dict:
        """Pickled and deep-copied without the last solve's normal equations (CHOLMOD handles
        cannot be pickled); a copy builds them anew on its next call and still warm-starts."""
        return {**self.__dict__, "_last": None}

    @property
    def timestamps(self) -> dict[int, float]:
        """Each node's time in seconds, by node id, for a smoother with ``lag_seconds``."""
        if self.fixed_lag is None or self.fixed_lag.seconds is None:
            raise ValueError("timestamps belong to a Smoother made with lag_seconds")
        return self.fixed_lag.timestamps

    @property
    def optimized(self) -> bool:
        """Whether the graph's values hold a solution of ``optimize`` (the next call warm-starts)."""
        return self.solution is not None

    def optimize(
        self,
        init: str = "auto",
        options: SolverOptions | None = None,
        callback: Callback | None = None,
        robust: str | RobustSpec | None = None,
        robust_edges: str | np.ndarray = "loops",
        robust_priors: bool = False,
        calibrate_noise: bool | None = False,
    ) -> Result:
        """Initialise the graph's values by ``init``, minimise its cost, and leave the solution
        in the graph's values; ``posegraph.optimize`` documents the arguments. A back end's
        calls do not check the noise unless asked (``calibrate_noise`` None or True): the check
        costs about a solve.

        "auto" on a smoother that solved before warm-starts (``warm_start``): the solved nodes
        keep their values, nodes added since are composed and refined alone; in least squares
        it restarts from chordal relaxation where the new measurements disagree with the
        solution (``warm_start.RESTART``), and solves nothing where all that was added hangs off
        a converged solution by a tree of edges (``warm_start.COMPOSED``), or, with
        ``options.skip_within``, where it could lower the optimum by at most that share of the
        cost (``warm_start.SKIPPED``; a later call solves). A GNC call carries
        the last run's decisions where the graph has only grown (``warm_start.previous_decisions``).
        ``summary.reused`` says what was reused."""
        options = options or SolverOptions()
        spec = (
            RobustSpec.parse(robust, robust_edges, robust_priors)
            if isinstance(robust, str)
            else robust
        )
        if self.fixed_lag is not None:
            return self._optimize_window(init, options, spec, calibrate_noise)
        began = time.perf_counter()
        kernel = None if spec is None else resolve(spec, self.graph)  # checked before any work
        input_error = cost(self.graph, kernel) if self.graph.initialized.all() else None
        start = self._start(init, kernel, options)
        initialization_time = time.perf_counter() - began
        solved = self._solve(start, kernel, options, callback)
        result, *weights = self._calibrate(solved, kernel, options, callback, calibrate_noise)
        summary = dataclasses.replace(
            result.summary,
            initialization=start.init,
            initialization_time=initialization_time,
            reused=start.reused + result.summary.reused,
            input_error=input_error,
            total_time=time.perf_counter() - began,
        )
        result = dataclasses.replace(result, summary=summary)
        self._keep(result, weights, kernel, options, start)
        return result

    def _keep(self, result: Result, weights, kernel, options: SolverOptions, start: Start) -> None:
        """Leave ``result``'s values in the graph and keep its ``Solution`` for the next call."""
        summary = result.summary
        final = (
            kernel is not None
            and kernel.spec.gnc
            and not (summary.termination in (STOPPED, TIME_LIMIT) or options.max_iterations == 0)
        )
        graph = self.graph
        graph.set_values(result.values, check=False)
        gnc = GncProblem(kernel.spec, kernel.measured) if final else None
        debt = 0.0 if start.debt is None else start.debt
        self.solution = Solution(
            graph.edges,
            graph.priors,
            *weights,
            graph.fixed.copy(),
            result.values,
            summary,
            gnc,
            debt,
        )

    def _optimize_window(
        self, init: str, options: SolverOptions, spec: RobustSpec | None, calibrate_noise
    ) -> Result:
        """A fixed-lag smoother's call: least squares over the window from the values it has."""
        if spec is not None or init != "auto" or calibrate_noise:
            raise ValueError(
                "a fixed-lag Smoother solves least squares from the values it holds: robust, "
                "init and calibrate_noise are not supported with lag"
            )
        result, graph = self.fixed_lag.update(self.graph, options), self.graph
        self.solution = Solution.least_squares(
            graph.edges, graph.priors, graph.fixed.copy(), result.values, result.summary
        )
        return result

    def _start(self, init: str, kernel: Kernel | None, options: SolverOptions) -> Start:
        """The graph's starting values, set by ``init`` (a warm start where the smoother solved
        before and ``init`` is "auto")."""
        graph, solution = self.graph, self.solution
        if init == "auto" and solution is not None:
            return warm_start.warm_started(self.graph, solution, kernel, options)
        if init == "file":
            graph.require_values("add them with values or use init='auto'")
        else:
            if init == "auto":
                init = "odometry" if kernel is not None else choose(graph)
            graph.set_values(initialize(graph, init), check=False)
        return Start(init)

    def _solve(
        self, start: Start, kernel: Kernel | None, options: SolverOptions, callback
    ) -> tuple[Result, np.ndarray, np.ndarray]:
        """The solve from the start values: (result, edge weights, prior weights)."""
        graph = self.graph
        if start.debt is not None:
            result = warm_start.composed_result(graph, self.solution, options, start)
            # a call solves nothing only where the graph grew by appending (``Growth.appended``)
            edge_weights, prior_weights = self.solution.appended_weights(graph.num_edges)
            if kernel is not None:  # GNC's decisions stand
                rejected = np.flatnonzero(~start.standing)
                summary = with_robust_record(result.summary, kernel, rejected, graph)
                result = dataclasses.replace(result, summary=summary)
            return result, edge_weights, prior_weights
        if kernel is None:
            result = self._solve_warm(graph, options, callback)
            return result, np.ones(graph.num_edges), np.ones(len(graph.priors))
        carried = (start.standing, start.decisions, start.graduate, start.search)
        outcome = robust_solve(graph, kernel, options, callback, self._solve_warm, *carried)
        return outcome.result, outcome.edge_weights, outcome.prior_weights

    def _calibrate(
        self,
        solved: tuple[Result, np.ndarray, np.ndarray],
        kernel: Kernel | None,
        options: SolverOptions,
        callback: Callback | None,
        calibrate_noise: bool | None,
    ) -> tuple[Result, np.ndarray, np.ndarray]:
        """``calibrate_noise`` (``calibration.calibrate``) after the first solve, where asked or,
        with None, in GNC at the default width; the summary records the noise check and the
        calibration."""
        automatic = calibrate_noise is None
        if automatic:
            calibrate_noise = kernel is not None and kernel.spec.gnc and kernel.spec.width is None
        stopped = solved[0].summary.termination in (STOPPED, TIME_LIMIT)
        if not calibrate_noise or stopped or options.max_iterations == 0:
            return solved
        solves = [solved]

        def again(after: Result | None = None, search=True, stage="calibrated") -> Result:
            decisions, graduate = None, after is None  # GNC anew, else settled from after's
            if kernel is not None and kernel.spec.gnc and not graduate:
                weights = next(solve[1:] for solve in solves if solve[0] is after)
                decisions = np.concatenate(weights)[: len(kernel.measured)] > 0
            start = Start("calibration", decisions=decisions, graduate=graduate, search=search)
            solves.append(self._solve(start, kernel, options, named_stages(callback, stage)))
            return solves[-1][0]

        began = time.perf_counter()
        covered = () if kernel is None else kernel_classes(self.graph, kernel.measured)
        second = anew = None
        if automatic and kernel is not None:  # GNC at the default width, from these values
            values = self.graph.values[np.arange(self.graph.num_nodes)]
            runs = FromStart(self.graph, kernel, values, again)
            second, anew = runs.second_opinion, runs.anew
        result, calibration, noise = calibrate(
            self.graph, solved[0], again, automatic, kernel is not None, covered, second, anew
        )
        summaries, elapsed = [s[0].summary for s in solves], time.perf_counter() - began
        summary = dataclasses.replace(
            in_turn_summary(result.summary, summaries, "noise check", elapsed),
            noise=[c.as_dict() for c in noise],
            calibration=None if calibration is None else calibration.as_dict(),
        )
        weights = next(solve[1:] for solve in solves if solve[0] is result)
        return dataclasses.replace(result, summary=summary), *weights

    def _solve_warm(
        self,
        graph: PoseGraph,
        options: SolverOptions,
        callback: Callback | None,
        weighting: Robustifier | None = None,
    ) -> Result:
        """``solve`` on the graph, reusing the last solve's normal equations (if the structure
        is unchanged; the solver grows them if the graph only grew) and linearisation (where it
        still holds), and keeping this solve's for the next."""
        previous = None
        if self._last is not None and self._last[0][1] == options.linear_solver:
            previous = self._last[1]
        system = self.current_system(options.linear_solver)
        result = solve(
            graph, options, callback, system=system, weighting=weighting, previous=previous
        )
        self._last = ((graph.structure_version, options.linear_solver), result)
        return result

    def current_system(self, linear_solver: str) -> NormalEquations | None:
        """The normal equations of the last solve with ``linear_solver``, if the graph's structure
        has not changed since (their pattern and symbolic factorisation still hold); else None."""
        system = self.last_system(linear_solver)
        if system is None or self._last[0][0] != self.graph.structure_version:
            return None
        return system

    def last_system(self, linear_solver: str) -> NormalEquations | None:
        """The normal equations of the last solve with ``linear_solver``, whatever changed since
        (a pattern that new ones may grow from), or None."""
        if self._last is None or self._last[0][1] != linear_solver:
            return None
        return self._last[1].system

    def current_normal_matrix(self, values, linear_solver: str) -> np.ndarray | None:
        """H's CSC data at ``values`` in ``current_system(linear_solver)``'s pattern, if the last
        least-squares solve of the graph's measurements linearised there; else None."""
        system = self.current_system(linear_solver)
        if system is None:
            return None
        return self._last[1].linearization.normal_matrix_for(self.graph, values, system)

    def weights(self) -> tuple[np.ndarray, np.ndarray]:
        """The weights of the graph's between edges and priors in the last solution
        (``Solution.weights_for``: 1 for those added since), or all 1 before any."""
        graph = self.graph
        if self.solution is None:
            return np.ones(graph.num_edges), np.ones(len(graph.priors))
        return self.solution.weights_for(graph.edges, graph.priors)

    def rejected(self) -> tuple[np.ndarray, np.ndarray]:
        """Masks over the between edges and over the priors of those that the last robust
        ``optimize`` rejected (``Solution.rejected_for``: none added since); none without one."""
        graph = self.graph
        if self.solution is None:
            return np.zeros(graph.num_edges, dtype=bool), np.zeros(len(graph.priors), dtype=bool)
        return self.solution.rejected_for(graph.edges, graph.priors)

    def without_rejected(self) -> PoseGraph:
        """A copy of the graph without the between edges and priors that the last robust
        ``optimize`` rejected: the inliers, to keep, to write or to solve in least squares."""
        edges, priors = self.rejected()
        inliers = self.graph.with_edges(~edges)
        inliers.priors = self.graph.priors.subset(~priors)
        return inliers

    def remove_edges(self, edges) -> None:
        """``PoseGraph.remove_edges``, the last solution's weights and rejections staying with
        the edges that remain (``Solution.without``)."""
        removed = measurement_mask(edges, self.graph.num_edges, "edge", "edges to remove")
        carried = self._carried()
        self.graph.remove_edges(removed)
        self._carry(carried, edges=removed)

    def remove_priors(self, priors) -> None:
        """``PoseGraph.remove_priors``, the last solution staying with the priors that remain."""
        removed = measurement_mask(priors, len(self.graph.priors), "prior", "priors to remove")
        carried = self._carried()
        self.graph.remove_priors(removed)
        self._carry(carried, priors=removed)

    def remove_nodes(self, node_ids) -> tuple[np.ndarray, np.ndarray]:
        """``PoseGraph.remove_nodes`` (a culled keyframe, with every edge and prior on it); the
        next call starts from the values that remain, and a robust one from the last run's
        decisions on the measurements that remain. Returns the masks of what went."""
        nodes = np.zeros(self.graph.num_nodes, dtype=bool)
        nodes[self.graph.index(node_ids)] = True
        carried = self._carried()
        edges, priors = self.graph.remove_nodes(node_ids)
        self._carry(carried, nodes, edges, priors)
        return edges, priors

    def _carried(self) -> Solution | None:
        """The solution, if its measurements still come first and unchanged in the graph (a
        removal can then carry it); else None, and no later call carries it anyway."""
        if self.fixed_lag is not None:
            raise ValueError("a fixed-lag Smoother's graph only grows: nothing can be removed")
        solution, graph = self.solution, self.graph
        if solution is None or not (
            graph.edges.starts_with(solution.edges) and graph.priors.starts_with(solution.priors)
        ):
            return None
        return solution

    def _carry(
        self,
        solution: Solution | None,
        nodes: np.ndarray | None = None,
        edges: np.ndarray | None = None,
        priors: np.ndarray | None = None,
    ) -> None:
        """After a removal (masks over the nodes, edges and priors as they were; None for none
        of them), keep what remains of the ``_carried`` solution (``Solution.without``)."""
        if solution is None:
            return

        def own(removed: np.ndarray | None, count: int) -> np.ndarray:
            return np.zeros(count, dtype=bool) if removed is None else removed[:count]

        self.solution = solution.without(
            own(nodes, len(solution.fixed)),
            own(edges, len(solution.edges)),
            own(priors, len(solution.priors)),
        )
