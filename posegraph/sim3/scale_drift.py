"""Sim(3) scale-drift correction of a monocular trajectory (Strasdat, Montiel & Davison 2010,
"Scale Drift-Aware Large Scale Monocular SLAM"; ORB-SLAM's essential-graph optimisation).

A monocular trajectory is an SE3 pose graph whose translations drift in scale. Lifted to Sim3
(every pose and odometry edge gets scale 1, with a configurable information on log-scale) and
given loop closures that carry their measured Sim3 (relative scale included), one Sim3
optimisation spreads the scale correction along the loops. Mapping back keeps each pose's
rotation and takes its corrected position; the per-pose scale is returned too.

Pose conventions are explicit: ``"world_from_camera"`` poses are T_w_c (x_w = R x_c + t; the
camera centre is t), ``"camera_from_world"`` poses are T_c_w. Edges always measure T_i_j, the pose
of node j in the frame of node i (``PoseGraph``'s between convention). Internally nodes are
world-from-camera: a node's Sim3 S_w_c maps camera coordinates in its local map's scale to the
world, so its SE3 pose is (R, t) and its scale s says how the local map's units relate to the
world's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph
from ..io.trajectories import as_se3
from ..lie import SE3, Sim3
from ..robust.spec import RobustSpec
from ..smoother import Smoother
from ..solvers import Callback, Result, SolverOptions
from .lifting import (
    check_scale_information,
    default_scale_information,
    lift_information,
    lift_se3,
    loop_scale_sigma,
)

CONVENTIONS = ("world_from_camera", "camera_from_world")


def _check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise ValueError(f"pose convention is one of {', '.join(CONVENTIONS)}, not {convention!r}")


def lift_graph(graph: PoseGraph, scale_information: float | None = None) -> PoseGraph:
    """An SE3 graph as a Sim3 graph: nodes, edges and priors get scale 1 and σ-information
    ``scale_information`` (None: ``default_scale_information`` of the edges); fixed nodes stay
    fixed (and so fix the scale gauge)."""
    if graph.group is not SE3:
        raise ValueError(f"lift_graph takes an SE3 graph, not {graph.group.__name__}")
    scale_information = lifting_scale_information(graph, scale_information)
    lifted = PoseGraph(Sim3)
    lifted.add_nodes(graph.node_ids, lift_se3(graph.values))
    ids = graph.node_ids
    lifted.add_edges(
        ids[graph.edges.i],
        ids[graph.edges.j],
        lift_se3(graph.edges.measurements),
        lift_information(graph.edges.information, scale_information),
    )
    if len(graph.priors):
        lifted.add_priors(
            ids[graph.priors.i],
            lift_se3(graph.priors.measurements),
            lift_information(graph.priors.information, scale_information),
        )
    lifted.fixed = graph.fixed.copy()
    return lifted


def lifting_scale_information(
    graph: PoseGraph, scale_information: float | None, loop_sigma: float | None = None
) -> float:
    """The σ-information ``lift_graph`` gives an SE3 graph: ``scale_information`` (checked
    positive and finite), or if None ``default_scale_information`` of its edges and of the
    scale change per edge that Sim3 loops call for (``loop_sigma``; None: no loops)."""
    check_scale_information(scale_information)
    if scale_information is not None:
        return scale_information
    return default_scale_information(graph.edges.information, graph.edges.measurements, loop_sigma)


def convert_convention(poses: SE3, convention: str) -> SE3:
    """World-from-camera poses in ``convention``, or poses in ``convention`` as world-from-camera:
    T_c_w = T_w_c⁻¹ either way (the conversion is its own inverse)."""
    _check_convention(convention)
    return poses if convention == "world_from_camera" else poses.inverse()


def sim3_to_se3(values: Sim3, convention: str = "world_from_camera") -> SE3:
    """Corrected SE3 poses of Sim3 nodes S_w_c: the rotation is kept and the position is the
    similarity's translation (the camera centre); returned in ``convention``."""
    return convert_convention(as_se3(values), convention)


@dataclasses.dataclass(frozen=True)
class ScaleDriftCorrection:
    """The corrected trajectory (in the convention asked for), per-pose scales, the smoother of
    the optimised Sim3 graph (what a robust run rejected: ``Smoother.rejected``) and the
    optimisation result; ``lifted_scale_information``, the σ-information an SE3 graph was
    lifted with (None if the graph given was Sim3)."""

    poses: SE3
    scales: np.ndarray
    node_ids: np.ndarray
    smoother: Smoother
    result: Result
    convention: str
    lifted_scale_information: float | None = None

    @property
    def graph(self) -> PoseGraph:
        """The optimised Sim3 graph."""
        return self.smoother.graph


def correct_scale_drift(
    graph: PoseGraph,
    scale_information: float | None = None,
    convention: str = "world_from_camera",
    options: SolverOptions | None = None,
    init: str = "auto",
    robust: str | RobustSpec | None = None,
    robust_edges: str | np.ndarray = "loops",
    robust_priors: bool = False,
    callback: Callback | None = None,
) -> ScaleDriftCorrection:
    """Correct the scale drift of a graph: an SE3 graph is lifted first, every edge with
    log-scale information ``scale_information`` (``lifting_scale_information``; its loops then
    say that both ends have one scale, which corrects drift only if their translations are
    metric: add Sim3 loops with ``add_sim3_loops`` instead); a Sim3 graph, such as a g2o file of
    SE3 odometry plus EDGE_SIM3 loops read by ``read_graph``, is optimised as it is.

    ``convention`` names how the returned ``poses`` are expressed. ``init`` is the initialisation
    (default "auto": chordal relaxation of rotations, log-scales and translations when the graph
    has loops, which copes with drift that dead reckoning cannot start from). ``robust``,
    ``robust_edges``, ``robust_priors`` and ``callback`` are ``optimize``'s: with
    ``robust="gnc"``, loop closures from place recognition that matched the wrong place are
    rejected (``result.summary.rejected_edges``).
    """
    _check_convention(convention)
    lifted_with = None
    if graph.group is SE3:
        lifted_with = lifting_scale_information(graph, scale_information)
        sim3 = lift_graph(graph, lifted_with)
    else:
        sim3 = graph.copy()
    if sim3.group is not Sim3:
        raise ValueError(
            f"scale-drift correction needs an SE3 or Sim3 graph, not {graph.group.__name__}"
        )
    smoother = Smoother(sim3)  # leaves the solution in ``sim3``
    result = smoother.optimize(
        init=init,
        options=options,
        callback=callback,
        robust=robust,
        robust_edges=robust_edges,
        robust_priors=robust_priors,
    )
    return ScaleDriftCorrection(
        poses=sim3_to_se3(result.values, convention),
        scales=np.asarray(result.values.scale).copy(),
        node_ids=sim3.node_ids.copy(),
        smoother=smoother,
        result=result,
        convention=convention,
        lifted_scale_information=lifted_with,
    )


def add_sim3_loops(
    graph: PoseGraph,
    i_ids,
    j_ids,
    measurements: Sim3,
    information: np.ndarray,
    scale_information: float | None = None,
) -> PoseGraph:
    """The graph lifted to Sim3 (if it is SE3) with loop closures i → j of measured Sim3
    T_i_j (relative scale s_j / s_i of the two local maps) added. The lift's log-scale
    information is ``scale_information``, or if None ``lifting_scale_information`` with the
    scale change per edge that these loops call for (``loop_scale_sigma``)."""
    if graph.group is not SE3:
        sim3 = graph.copy()
        sim3.add_edges(i_ids, j_ids, measurements, information)
        return sim3
    lifted_with = lifting_scale_information(graph, scale_information)
    sim3 = lift_graph(graph, lifted_with)
    loops = sim3.add_edges(i_ids, j_ids, measurements, information)
    if scale_information is None:
        ends = np.stack([sim3.edges.i, sim3.edges.j], axis=1)
        sigma = loop_scale_sigma(
            ends[: graph.num_edges], ends[loops], sim3.edges.measurements.scale[loops]
        )
        relaxed = lifting_scale_information(graph, None, sigma)
        if relaxed != lifted_with:
            return add_sim3_loops(graph, i_ids, j_ids, measurements, information, relaxed)
    return sim3
