"""Seeded false loop closures for any graph, to test robust estimation.

``add_false_loops`` joins random pairs of non-consecutive nodes with edges whose measurement is
a random relative pose (uniform rotation; translation uniform within the extent of the graph's
own edge translations) and whose information is copied from a random true edge, so that
nothing but their inconsistency gives them away.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from posegraph.graph import PoseGraph
from posegraph.initialization import odometry_mask


def add_false_loops(graph: PoseGraph, fraction: float, seed: int) -> tuple[PoseGraph, np.ndarray]:
    """A copy of ``graph`` in which false loops make up ``fraction`` of all loop closures
    (edges between non-consecutive nodes), and the mask of the false edges."""
    if not 0 <= fraction < 1:
        raise ValueError(f"the outlier fraction must be in [0, 1), not {fraction}")
    rng = np.random.default_rng(seed)
    true_loops = int((~odometry_mask(graph)).sum())
    count = int(round(fraction / (1.0 - fraction) * true_loops))
    n = graph.num_nodes
    i = rng.integers(0, n, size=4 * count + 16)
    j = rng.integers(0, n, size=i.size)
    keep = np.abs(i - j) > 1
    i, j = i[keep][:count], j[keep][:count]
    extent = np.abs(graph.edges.measurements.translation).max(axis=0)
    random_poses = graph.group.sample(rng, (i.size,))
    measurements = dataclasses.replace(
        random_poses, translation=rng.uniform(-extent, extent, size=(i.size, extent.size))
    )
    information = graph.edges.information[rng.integers(0, graph.num_edges, size=i.size)]
    corrupted = graph.copy()
    corrupted.add_edges(graph.node_ids[i], graph.node_ids[j], measurements, information)
    false_mask = np.zeros(corrupted.num_edges, dtype=bool)
    false_mask[graph.num_edges :] = True
    return corrupted, false_mask


def rejection_rates(
    graph: PoseGraph, false: np.ndarray, rejected: np.ndarray
) -> tuple[float, float]:
    """For ``rejected`` edge indices of ``graph`` with the false-loop mask ``false``: the share of
    the false loops rejected, and the share of the true loop closures (edges between
    non-consecutive nodes that are not false) wrongly rejected."""
    is_rejected = np.zeros(graph.num_edges, dtype=bool)
    is_rejected[rejected] = True
    true_loops = ~odometry_mask(graph) & ~false
    return (
        float((is_rejected & false).sum() / max(false.sum(), 1)),
        float((is_rejected & true_loops).sum() / max(true_loops.sum(), 1)),
    )
