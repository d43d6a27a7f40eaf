"""SE3 → Sim3 lifting: similarities of scale 1, and information with a σ (log-scale) block."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph
from ..lie import SE3, Sim3


def lift_se3(element: SE3, scale: float | np.ndarray = 1.0) -> Sim3:
    """The similarities (R, t, s) of SE3 elements, with scale ``scale``."""
    batch = element.batch_shape
    return Sim3(
        element.rotation, element.translation, np.broadcast_to(np.asarray(scale, float), batch)
    )


def check_scale_information(scale_information: float | None) -> None:
    """Refuse a log-scale information that is not a positive finite number (None: the default)."""
    if scale_information is not None and not 0 < scale_information < np.inf:
        raise ValueError(
            f"scale information must be positive and finite, not {scale_information:g}"
        )


def lift_information(information: np.ndarray, scale_information: float) -> np.ndarray:
    """(…, 7, 7) Sim3 information over (ρ, φ, σ) from (…, 6, 6) SE3 information over (ρ, φ)."""
    information = np.asarray(information, float)
    out = np.zeros(information.shape[:-2] + (7, 7))
    out[..., :6, :6] = information
    out[..., 6, 6] = scale_information
    return out


LOOPS_SEARCHED = 64
"""At most this many loops, evenly spaced, are searched for their path (``loop_scale_sigma``)."""

PATH_ENTRIES = 1 << 22
"""Hop counts held at once while searching: 32 MB."""


def default_scale_information(
    se3_information: np.ndarray, se3_measurements: SE3, loop_sigma: float | None = None
) -> float:
    """Information on log-scale for lifted SE3 edges: median over edges of λ_t · |Δt|², with
    λ_t = tr(Ω_ρρ)/3, so that a relative scale change costs about as much as the translation
    error it could explain. Much weaker and node scales absorb translation residuals (the
    positions are then barely constrained); much stronger and loops cannot re-scale.

    Where the loops call for a larger change per edge (``loop_sigma``, from
    ``loop_scale_sigma``) than the 1σ that value allows, it is 1/loop_sigma² instead: a lift
    that allows less than the change the loops measured makes them look false to a robust
    kernel, and strains the odometry against them in least squares."""
    value = 1.0
    if len(se3_information):
        translation_weight = np.trace(se3_information[:, :3, :3], axis1=1, axis2=2) / 3.0
        step = np.einsum("mi,mi->m", se3_measurements.translation, se3_measurements.translation)
        median = float(np.median(translation_weight * step))
        value = median if median > 0 else 1.0
    if loop_sigma is not None and loop_sigma * np.sqrt(value) > 1.0:
        return loop_sigma**-2
    return value


def loop_scale_sigma(
    edge_ends: np.ndarray, loop_ends: np.ndarray, loop_scales: np.ndarray
) -> float | None:
    """The 1σ change of log-scale per lifted edge that Sim3 loops call for: σ² is the median
    over loops of (log s)² / k^(3/2), k the number of lifted edges on the shortest path between
    the loop's ends. A steady drift δ per edge makes log s = kδ; the lift's model, independent
    steps of σ, makes log s ≈ σ√k. This is the geometric mean of the two estimates, δ² =
    (log s)²/k² and σ² = (log s)²/k. On 87 fuzzed monocular sequences with 10–30% false loops
    (drift up to ±2% per keyframe, steady or with sign flips), GNC failed on 3 with it, on 7
    with δ and on 1 with the random walk's σ; but least squares ended over 20% further from the
    ground truth with that σ than with δ on 16 of 51, with this one on 3.

    ``edge_ends`` and ``loop_ends`` are (…, 2) node ids of the lifted edges and of the loops,
    ``loop_scales`` the loops' measured relative scales. Loops whose ends the lifted edges do
    not join, or whose scale is not a positive number, are left out, and at most
    ``LOOPS_SEARCHED`` loops are searched; None if no loop is left or none saw a change."""
    import scipy.sparse.csgraph  # on use: only scale drift's loops need it

    edge_ends = np.asarray(edge_ends, np.int64).reshape(-1, 2)
    loop_ends = np.asarray(loop_ends, np.int64).reshape(-1, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_scale = np.log(np.asarray(loop_scales, float))
    usable = np.flatnonzero(np.isfinite(log_scale) & np.isin(loop_ends, edge_ends).all(axis=1))
    if usable.size == 0:  # no lifted edges leave no loop usable too
        return None
    usable = usable[np.linspace(0, usable.size - 1, min(usable.size, LOOPS_SEARCHED)).astype(int)]
    nodes = np.unique(edge_ends)
    edges = np.searchsorted(nodes, edge_ends)
    adjacency = scipy.sparse.coo_matrix(
        (np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(nodes.size, nodes.size)
    ).tocsr()
    starts = np.searchsorted(nodes, loop_ends[usable, 0])
    ends = np.searchsorted(nodes, loop_ends[usable, 1])
    hops = np.empty(usable.size)
    chunk = max(1, PATH_ENTRIES // nodes.size)
    for first in range(0, usable.size, chunk):
        rows = slice(first, first + chunk)
        distances = scipy.sparse.csgraph.shortest_path(
            adjacency, directed=False, unweighted=True, indices=starts[rows]
        )
        hops[rows] = distances[np.arange(distances.shape[0]), ends[rows]]
    joined = np.isfinite(hops) & (hops > 0)
    if not joined.any():
        return None
    variance = float(np.median(log_scale[usable][joined] ** 2 / hops[joined] ** 1.5))
    return float(np.sqrt(variance)) if variance > 0 else None


def lift_se3_lines(
    graph: PoseGraph, edges: np.ndarray, priors: np.ndarray, scale_information: float | None
) -> float:
    """Give the edges and priors of a Sim3 graph that were SE3 lines (masks ``edges`` and
    ``priors``; read at scale 1 with no log-scale information) the log-scale information
    ``scale_information``, or if None ``default_scale_information`` of those edges and of the
    change per edge that the other (Sim3) edges call for (``loop_scale_sigma``); returns it."""
    check_scale_information(scale_information)
    lifted = graph.edges.subset(edges)
    if scale_information is None:
        loops = graph.edges.subset(~edges)
        sigma = loop_scale_sigma(  # node indices serve as the ids
            np.stack([lifted.i, lifted.j], axis=1),
            np.stack([loops.i, loops.j], axis=1),
            loops.measurements.scale,
        )
        odometry = lifted.measurements
        scale_information = default_scale_information(
            lifted.information[:, :6, :6], SE3(odometry.rotation, odometry.translation), sigma
        )
    for kind, mask in (("edges", edges), ("priors", priors)):
        information = getattr(graph, kind).information.copy()
        information[mask, 6, 6] = scale_information
        setattr(graph, kind, dataclasses.replace(getattr(graph, kind), information=information))
    graph.structure_version += 1
    return scale_information
