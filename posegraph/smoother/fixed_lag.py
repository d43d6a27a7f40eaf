"""Fixed-lag smoothing: the newest poses optimised, older ones marginalised into a dense Gaussian
prior on the poses still connected to them, as gtsam's ``BatchFixedLagSmoother`` does (with its
default ``enforceConsistency``).

Each call optimises the poses not yet marginalised, then marginalises those older than the
window: the measurements on them are linearised at the current estimate and the poses
eliminated (``marginal.marginalized``), leaving a ``GaussianPrior`` on their neighbours. The
poses under that prior keep the linearisation point it was computed at (first-estimate
Jacobians, Huang, Mourikis and Roumeliotis 2009), their estimate being that point moved by a
tangent ``delta``, so the prior stays the model it was built as. Marginalised poses keep their
last estimate in the graph's values."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..graph import EdgeSet, PoseGraph
from ..init.choice import choose, initialize
from ..lie import LieGroup
from ..problem.factors import chi2
from ..solvers import (
    GRADIENT_BELOW_TOLERANCE,
    MAX_ITERATIONS,
    IterationRecord,
    Result,
    SolverOptions,
    Summary,
)
from .band import BandMatrix
from .composition import compose_new_nodes
from .marginal import GaussianPrior, Quadratic, marginalized, quadratic

INITIAL_DAMPING = 1e-5
"""λ at the start of each call; λ·I damps the step towards the current tangents, and grows or
shrinks by ``DAMPING_FACTOR`` within [``MIN_DAMPING``, ``MAX_DAMPING``] (gtsam's
``BatchFixedLagSmoother::optimize`` with its default Levenberg-Marquardt parameters)."""
DAMPING_FACTOR = 10.0
MIN_DAMPING = 1e-10
MAX_DAMPING = 1e5
CONVERGED = "error decrease at most relative_decrease"
"""The termination of a call whose last iteration lowered the error by at most
``relative_decrease`` of it (or not at all)."""


@dataclasses.dataclass
class _Window:
    """The nodes not yet marginalised (graph indices ``nodes``) with the measurements on them
    renumbered to the window, the values at which it is linearised (pinned nodes at their
    linearisation points), each node's tangent from there (zero but for pinned nodes), and the
    positions of the nodes optimised (−1 for held ones)."""

    nodes: np.ndarray
    edges: EdgeSet
    priors: EdgeSet
    prior: GaussianPrior | None
    linearization: LieGroup
    delta: np.ndarray
    position: np.ndarray
    pinned: np.ndarray

    def estimate(self) -> LieGroup:
        return self.linearization.retract(self.delta)

    def error(self, delta: np.ndarray) -> float:
        """½ Σ rᵀΩr of the window's measurements with tangents ``delta``, plus the prior's."""
        error = 0.5 * chi2(self.linearization.retract(delta), self.edges, self.priors)
        if self.prior is not None:
            error += self.prior.error(delta[self.prior.nodes])
        return error


class FixedLag:
    """What a fixed-lag ``Smoother`` keeps between calls: which nodes are marginalised, the
    pinned nodes' linearisation points and tangents, the ``GaussianPrior`` (on graph indices),
    the measurements not yet absorbed into it, and the held nodes."""

    def __init__(self, lag: int | None = None, seconds: float | None = None) -> None:
        if (lag is None) == (seconds is None):
            raise ValueError("a fixed lag is given in poses (lag) or in seconds, not both")
        if lag is not None and not (isinstance(lag, (int, np.integer)) and lag >= 1):
            raise ValueError(f"lag is the number of newest poses kept (≥ 1), not {lag!r}")
        if seconds is not None and not (np.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"lag_seconds is a duration (≥ 0), not {seconds!r}")
        self.lag = None if lag is None else int(lag)
        self.seconds = seconds
        self.timestamps: dict[int, float] = {}
        """Each node's time in seconds, by node id (with a lag in seconds)."""
        self.marginalized = np.zeros(0, dtype=bool)
        self.pinned = np.zeros(0, dtype=bool)
        self.linearization_points: LieGroup | None = None
        self.delta = np.zeros((0, 0))
        self.prior: GaussianPrior | None = None
        self.open_edges = np.zeros(0, dtype=np.int64)
        self.open_priors = np.zeros(0, dtype=np.int64)
        self.seen = (0, 0)
        """How many edges and priors of the graph the state has taken in."""
        self.held = np.zeros(0, dtype=np.int64)

    @property
    def span(self) -> str:
        """The window's length, in words."""
        return f"{self.lag} poses" if self.lag is not None else f"{self.seconds:g} s"

    def _old(self, graph: PoseGraph, nodes: np.ndarray) -> np.ndarray:
        """Which of the window's ``nodes`` (graph indices, in order) leave it: all but the
        newest ``lag``, or those stamped more than ``seconds`` before the newest (as gtsam's
        ``findKeysBefore``)."""
        if self.lag is not None:
            old = np.zeros(nodes.size, dtype=bool)
            old[: max(nodes.size - self.lag, 0)] = True
            return old
        ids = graph.node_ids[nodes].tolist()
        missing = [node for node in ids if node not in self.timestamps]
        if missing:
            raise ValueError(
                f"node {missing[0]} has no timestamp: a lag in seconds needs "
                "smoother.timestamps[node_id] = seconds for every node"
            )
        stamps = np.array([self.timestamps[node] for node in ids])
        return stamps < stamps.max() - self.seconds

    def update(self, graph: PoseGraph, options: SolverOptions) -> Result:
        """Take in what was added to ``graph``, optimise the window (``_optimize``), leave the
        estimates in the graph's values and marginalise the poses older than the lag."""
        began = time.perf_counter()
        self._grow(graph)
        init = self._initialize(graph)
        window = self._window(graph)
        old = self._old(graph, window.nodes)
        records, termination, initial, final, held = _optimize(window, options, began)
        graph.set_values(graph.values.set_at(window.nodes, window.estimate()), check=False)
        self.delta[window.nodes] = window.delta
        self._marginalize(graph, window, old)
        free = int(np.count_nonzero(window.position >= 0))
        summary = Summary(
            method="lm",
            linear_solver=held,
            initial_error=initial,
            final_error=final,
            iterations=records,
            termination=termination,
            converged=termination in (CONVERGED, GRADIENT_BELOW_TOLERANCE),
            phase_times={},
            total_time=time.perf_counter() - began,
            num_variables=free * graph.group.dof,
            reused=(
                f"fixed-lag window ({self.span}; {int(self.marginalized.sum())} marginalised)",
            ),
            initialization=init,
        )
        return Result(graph.values, summary)

    def _grow(self, graph: PoseGraph) -> None:
        """Extend the state to nodes and measurements added since; refuse a new measurement on
        a marginalised node, and a graph that changed other than by growing."""
        edges, priors = graph.edges, graph.priors
        added = graph.num_nodes - self.marginalized.size
        if added < 0 or len(edges) < self.seen[0] or len(priors) < self.seen[1]:
            raise ValueError("a fixed-lag smoother's graph only grows: nothing can be removed")
        group, d = graph.group, graph.group.dof
        if self.linearization_points is None:
            self.linearization_points, self.delta = group.identity((0,)), np.zeros((0, d))
            self.held = graph.gauge_nodes()
        self.marginalized = np.concatenate([self.marginalized, np.zeros(added, dtype=bool)])
        self.pinned = np.concatenate([self.pinned, np.zeros(added, dtype=bool)])
        self.delta = np.concatenate([self.delta, np.zeros((added, d))])
        self.linearization_points = group.concatenate(
            [self.linearization_points, group.identity((added,))]
        )
        new_edges = np.arange(self.seen[0], len(edges))
        new_priors = np.arange(self.seen[1], len(priors))
        late = self.marginalized[edges.i[new_edges]] | self.marginalized[edges.j[new_edges]]
        late_priors = self.marginalized[priors.i[new_priors]]
        if late.any() or late_priors.any():
            node = (edges.i[new_edges[late]] if late.any() else priors.i[new_priors])[0]
            raise ValueError(
                f"a measurement added on node {int(graph.node_ids[node])}, which left the "
                f"fixed-lag window of {self.span} and was marginalised: use a longer lag, "
                "or a Smoother without one for loop closures to old poses"
            )
        self.open_edges = np.concatenate([self.open_edges, new_edges])
        self.open_priors = np.concatenate([self.open_priors, new_priors])
        self.seen = (len(edges), len(priors))

    def _initialize(self, graph: PoseGraph) -> str:
        """Values for the nodes added without: composed from those with values, or, on the
        first call with none, the graph's own initialisation."""
        if graph.initialized.all():
            return "file"
        if not graph.initialized.any():
            init = choose(graph)
            graph.set_values(initialize(graph, init), check=False)
            return init
        compose_new_nodes(graph, ~graph.initialized)
        return "warm start"

    def _window(self, graph: PoseGraph) -> _Window:
        """The nodes not marginalised, their measurements and prior, renumbered to them."""
        nodes = np.flatnonzero(~self.marginalized)
        local = np.full(graph.num_nodes, -1, dtype=np.int64)
        local[nodes] = np.arange(nodes.size)
        free = np.ones(nodes.size, dtype=bool)
        free[local[self.held[~self.marginalized[self.held]]]] = False
        free[local[np.flatnonzero(graph.fixed & ~self.marginalized)]] = False
        position = np.full(nodes.size, -1, dtype=np.int64)
        position[free] = np.arange(np.count_nonzero(free))
        pinned = self.pinned[nodes]
        values = graph.values[nodes]
        prior = self.prior
        if prior is not None:
            prior = dataclasses.replace(prior, nodes=local[prior.nodes])
        return _Window(
            nodes,
            graph.edges.subset(self.open_edges).reindexed(local),
            graph.priors.subset(self.open_priors).reindexed(local),
            prior,
            values.set_at(np.flatnonzero(pinned), self.linearization_points[nodes[pinned]]),
            self.delta[nodes],
            position,
            pinned,
        )

    def _marginalize(self, graph: PoseGraph, window: _Window, old: np.ndarray) -> None:
        """Eliminate the window's ``old`` nodes with the measurements on them (and the prior),
        leaving a ``GaussianPrior`` on the others they reach, which are pinned."""
        if not old.any():
            return
        edges, priors = window.edges, window.priors
        removed_edges = old[edges.i] | old[edges.j]
        removed_priors = old[priors.i]
        touched = np.zeros(window.nodes.size, dtype=bool)
        touched[edges.i[removed_edges]] = touched[edges.j[removed_edges]] = True
        touched[priors.i[removed_priors]] = True
        if window.prior is not None:
            touched[window.prior.nodes] = True
        touched &= window.position >= 0
        position = np.full(window.nodes.size, -1, dtype=np.int64)
        position[touched] = np.arange(np.count_nonzero(touched))
        model = quadratic(
            window.linearization,
            edges.subset(removed_edges),
            priors.subset(removed_priors),
            position,
            window.prior,
        )
        kept = touched & ~old
        hessian, gradient, constant = marginalized(model, kept[touched], graph.group.dof)
        nodes = window.nodes[kept]
        self.prior = GaussianPrior(nodes, hessian, gradient, constant) if nodes.size else None
        newly = kept & ~window.pinned
        self.linearization_points = self.linearization_points.set_at(
            window.nodes[newly], window.linearization[newly]
        )
        gone = window.nodes[old]
        self.pinned[nodes] = True
        self.pinned[gone] = False
        self.delta[gone] = 0.0
        self.marginalized[gone] = True
        self.open_edges = self.open_edges[~removed_edges]
        self.open_priors = self.open_priors[~removed_priors]


def _optimize(window: _Window, options: SolverOptions, began: float):
    """Levenberg-Marquardt over the window's tangents, as gtsam's ``BatchFixedLagSmoother``: each
    iteration linearises at the window's linearisation point and tries λ until the error falls
    (then λ ÷ 10) or λ passes ``MAX_DAMPING``. Stops after ``max_iterations``, when an
    iteration lowers the error by no more than ``relative_decrease`` of it, when the model
    predicts no more than that for an iteration's first step, or when the model's gradient
    falls below ``gradient_tolerance`` (as in ``solve``). In the last two cases no step is
    tried: near the minimum, or where the window fits its measurements exactly, the actual
    decrease is round-off and every λ would be tried in vain. Returns (records, termination,
    initial error, final error, how the last model's H was held: ``Quadratic.storage``)."""
    error = initial = window.error(window.delta)
    records, damping, held = [], INITIAL_DAMPING, "dense"
    free = window.position >= 0
    if error <= 0.0 or not free.any():
        return records, CONVERGED, initial, error, held
    d = window.delta.shape[-1]
    for iteration in range(1, options.max_iterations + 1):
        model = quadratic(
            window.linearization, window.edges, window.priors, window.position, window.prior
        )
        held = model.storage
        current = window.delta[free].reshape(-1)
        if np.max(np.abs(model.hessian @ current - model.gradient)) < options.gradient_tolerance:
            return records, GRADIENT_BELOW_TOLERANCE, initial, error, held
        previous = error
        first = True
        while True:
            step = _solve(model, damping, current)
            if step is None:  # not positive definite at this λ: a rejected step
                step, trial = current, np.inf
            else:
                if first and model.decrease(current, step) <= options.relative_decrease * error:
                    return records, CONVERGED, initial, error, held
                delta = window.delta.copy()
                delta[free] = step.reshape(-1, d)
                trial = window.error(delta)
            first = False
            accepted = trial < error
            records.append(
                IterationRecord(
                    iteration,
                    min(trial, error),
                    damping,
                    float(np.linalg.norm(step - current)),
                    accepted,
                    time.perf_counter() - began,
                )
            )
            if accepted:
                error = trial
                _accept(window, delta, free)
                damping = max(damping / DAMPING_FACTOR, MIN_DAMPING)
                break
            if damping >= MAX_DAMPING:
                break
            damping *= DAMPING_FACTOR
        decrease = previous - error
        if decrease <= 0 or decrease <= options.relative_decrease * previous:
            return records, CONVERGED, initial, error, held
    return records, MAX_ITERATIONS, initial, error, held


def _accept(window: _Window, delta: np.ndarray, free: np.ndarray) -> None:
    """Move the window to accepted tangents: free nodes are relinearised there, pinned ones keep
    their point and take the tangent."""
    moved = np.flatnonzero(free & ~window.pinned)
    window.linearization = window.linearization.set_at(
        moved, window.linearization[moved].retract(delta[moved])
    )
    window.delta[moved] = 0.0
    window.delta[window.pinned] = delta[window.pinned]


def _solve(model: Quadratic, damping: float, current: np.ndarray) -> np.ndarray | None:
    """The tangents that minimise the model plus ½ λ ‖δ − current‖²: (H + λI) δ = g + λ current;
    None where H + λI is not numerically positive definite. A band or dense H is factorised by
    LAPACK's band or dense Cholesky directly (scipy.linalg's wrappers cost more than a small
    window's factorisation)."""
    hessian, rhs = model.hessian, model.gradient + damping * current
    if isinstance(hessian, (BandMatrix, np.ndarray)):
        from scipy.linalg import lapack  # on use: a start without a fixed-lag smoother does without

        if isinstance(hessian, BandMatrix):
            band = hessian.lower()
            band[0] += damping
            factor, failed = lapack.dpbtrf(band, lower=1)
            solve = lapack.dpbtrs
        else:
            factor, failed = lapack.dpotrf(hessian + damping * np.eye(rhs.size), lower=True)
            solve = lapack.dpotrs
        if failed:
            return None
        step, _ = solve(factor, rhs, lower=1)
        return step if np.isfinite(step).all() else None
    import scipy.sparse.linalg

    damped = (hessian + damping * scipy.sparse.identity(rhs.size)).tocsc()
    step = scipy.sparse.linalg.spsolve(damped, rhs)
    return step if np.isfinite(step).all() else None
