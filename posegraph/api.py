"""The one-call entry point: ``optimize`` a graph once, without keeping anything for later."""

from __future__ import annotations

import numpy as np

from .graph import PoseGraph
from .robust.spec import RobustSpec
from .smoother import Smoother
from .solvers import Callback, Result, SolverOptions


def optimize(
    graph: PoseGraph,
    init: str = "auto",
    options: SolverOptions | None = None,
    callback: Callback | None = None,
    robust: str | RobustSpec | None = None,
    robust_edges: str | np.ndarray = "loops",
    robust_priors: bool = False,
    calibrate_noise: bool | None = None,
) -> Result:
    """Initialise the graph's values by ``init``, minimise its cost, and leave the solution in
    ``graph.values``. A back end that calls again after every keyframe keeps a ``Smoother``,
    which warm-starts; this call starts afresh.

    ``init``: "auto" (chordal relaxation for a graph with loops, or odometry when ``robust`` is
    set, the odometry chain being trusted), "file", "odometry", "spanning-tree" or "chordal"
    (``posegraph.init.choice.initialize``). ``options``: the solver's (``SolverOptions``).
    ``callback`` receives every iteration and stops the run by returning True.
    ``robust``: None for least squares; "gnc" for graduated non-convexity with a truncated
    least-squares kernel (``posegraph.robust.gnc``); or a kernel "huber", "cauchy",
    "geman-mcclure", "tukey", "dcs"; each optionally ":WIDTH" in Mahalanobis units (by default,
    per measurement, √χ²_k for the k directions it weighs: ``robust.spec.resolve``), or a
    ``RobustSpec``. It covers ``robust_edges`` ("loops", "all", or a boolean mask over the
    between edges or their indices) and, with ``robust_priors``, the priors (GNSS fixes, say;
    ``posegraph.robust.anchoring``). The summary lists the rejected edges and priors
    (s = rᵀΩr > width²).

    ``calibrate_noise``: True scales each class's information (odometry, loop closures,
    priors) by its inliers' χ² per redundant degree of freedom and solves again, until the
    scales settle (``posegraph.robust.calibration``); None does so in GNC at the default width
    where GNC kept gross outliers (measurements that fail the χ² test tenfold under the noise
    the kept residuals show); False never. The graph's information is left
    scaled, and the summary records the scales (``calibration``) and the noise check (``noise``)."""
    smoother = Smoother(graph)
    return smoother.optimize(
        init, options, callback, robust, robust_edges, robust_priors, calibrate_noise
    )
