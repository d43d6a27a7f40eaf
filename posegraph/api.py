"""The one-call entry point: initialise, then optimise, optionally robustly."""

from __future__ import annotations

import time

import numpy as np

from .factors import between_residuals, weighted_squares
from .gnc import gnc_tls
from .graph import PoseGraph
from .initialization import choose, initialize, odometry_mask
from .robust import Robustifier, RobustKernel, default_width
from .solvers import Callback, Result, SolverOptions
from .solvers import optimize as solve

ROBUST_EDGE_CLASSES = ("loops", "all")
GNC_QUANTILE = 0.999
"""Default TLS threshold: an inlier's s = rᵀΩr exceeds √χ²_dof(0.999) once in a thousand."""
KERNEL_QUANTILE = 0.95
"""Default width of the IRLS kernels (Huber, Cauchy, …): √χ²_dof(0.95), Huber's usual choice."""


def robust_mask(graph: PoseGraph, edges: str) -> np.ndarray:
    """Which between edges a robust kernel applies to: "loops" (not between consecutive nodes)
    or "all"."""
    if edges == "loops":
        return ~odometry_mask(graph)
    if edges == "all":
        return np.ones(graph.num_edges, dtype=bool)
    raise ValueError(f"robust edges are {' or '.join(ROBUST_EDGE_CLASSES)}, not {edges!r}")


def optimize(
    graph: PoseGraph,
    init: str = "auto",
    options: SolverOptions | None = None,
    callback: Callback | None = None,
    robust: str | None = None,
    robust_edges: str = "loops",
) -> Result:
    """Initialise the graph's values by ``init``, then minimise its cost.

    ``init``: see ``posegraph.initialization.initialize``; "auto" picks chordal relaxation for
    graphs with loops, or odometry when ``robust`` is set (the odometry chain is trusted).
    ``robust``: None for least squares; "gnc" for graduated non-convexity with a truncated
    least-squares kernel (``posegraph.gnc``); or a kernel "huber", "cauchy", "geman-mcclure",
    "tukey", "dcs"; each optionally ":WIDTH" in Mahalanobis units (default ``GNC_QUANTILE`` or
    ``KERNEL_QUANTILE``), applied to ``robust_edges``. The summary lists the rejected edges
    (s = rᵀΩr > width²).

    The graph's values are replaced by the initial ones; the result holds the optimum.
    """
    options = options or SolverOptions()
    start = time.perf_counter()
    if init == "auto":
        init = "odometry" if robust else choose(graph)
    if init != "file":
        graph.set_values(initialize(graph, init))
    init_time = time.perf_counter() - start

    rejected = np.zeros(0, dtype=np.int64)
    if robust is None:
        result = solve(graph, options, callback)
    else:
        mask = robust_mask(graph, robust_edges)
        name, _, width_text = robust.partition(":")
        name = name.strip().lower()
        gnc = name in ("gnc", "tls")
        quantile = GNC_QUANTILE if gnc else KERNEL_QUANTILE
        width = float(width_text) if width_text else default_width(graph.group.dof, quantile)
        if gnc:
            outcome = gnc_tls(graph, mask, width, options)
            result, rejected = outcome.result, outcome.rejected
        else:
            kernel = RobustKernel(name, width)
            result = solve(graph, options, callback, weighting=Robustifier(kernel, mask))
            s = weighted_squares(
                between_residuals(result.values, graph.edges), graph.edges.information
            )
            rejected = np.flatnonzero(mask & (s > width**2))
        result.summary.robust = f"{name}:{width:.6g}"
        result.summary.rejected_edges = rejected.tolist()
    result.summary.initialization = init
    result.summary.initialization_time = init_time
    result.summary.total_time = time.perf_counter() - start
    return result
