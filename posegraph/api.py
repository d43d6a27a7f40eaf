"""The one-call entry point: initialise, then optimise."""

from __future__ import annotations

import time

from .graph import PoseGraph
from .initialization import initialize
from .solvers import Callback, Result, SolverOptions
from .solvers import optimize as solve


def optimize(
    graph: PoseGraph,
    init: str = "file",
    options: SolverOptions | None = None,
    callback: Callback | None = None,
) -> Result:
    """Initialise the graph's values by ``init`` (see ``posegraph.initialization.initialize``),
    then minimise ½ Σ rᵀΩr. The graph's values are replaced by the initial ones; the result
    holds the optimum and a summary that records the initialisation and its time."""
    start = time.perf_counter()
    if init != "file":
        graph.set_values(initialize(graph, init))
    init_time = time.perf_counter() - start
    result = solve(graph, options, callback)
    result.summary.initialization = init
    result.summary.initialization_time = init_time
    result.summary.total_time += init_time
    return result
