"""Seeded false loop closures and false pose fixes for any graph, to test robust estimation.

``add_false_loops`` joins random pairs of non-consecutive nodes with edges whose measurement is
a random relative pose (uniform rotation; translation uniform within the extent of the graph's
own edge translations) and whose information is copied from a random true edge, so that
nothing but their inconsistency gives them away. ``add_false_loops_anywhere`` draws them
otherwise, as a place recognition that matched the wrong place would: half between nearby
nodes (2 to ``NEARBY`` ids apart), half between distant ones, each a random relative pose
anywhere within the map's extent, with the information of one of the file's own loops.

``add_fixes`` adds absolute pose fixes (priors, as from GNSS with a heading) around the true
poses, of which a share are false: a random pose within the extent of the true positions, with
the same information as the true fixes.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from posegraph.graph import PoseGraph, odometry_mask
from posegraph.lie import LieGroup
from posegraph.problem.factors import information_root


def add_false_loops(graph: PoseGraph, fraction: float, seed: int) -> tuple[PoseGraph, np.ndarray]:
    """A copy of ``graph`` in which false loops make up ``fraction`` of all loop closures
    (edges between non-consecutive nodes), and the mask of the false edges."""
    _check_fraction(fraction)
    rng = np.random.default_rng(seed)
    true_loops = int((~odometry_mask(graph)).sum())
    count = int(round(fraction / (1.0 - fraction) * true_loops))
    n = graph.num_nodes
    i = rng.integers(0, n, size=4 * count + 16)
    j = rng.integers(0, n, size=i.size)
    keep = np.abs(i - j) > 1
    i, j = i[keep][:count], j[keep][:count]
    extent = np.abs(graph.edges.measurements.translation).max(axis=0)
    measurements = _random_poses(graph.group, rng, i.size, -extent, extent)
    information = graph.edges.information[rng.integers(0, graph.num_edges, size=i.size)]
    return _with_false_edges(graph, i, j, measurements, information)


NEARBY = 20
"""``add_false_loops_anywhere``'s nearby pairs are at most this many ids apart; its distant
ones at least this many."""


def add_false_loops_anywhere(
    graph: PoseGraph, fraction: float, seed: int
) -> tuple[PoseGraph, np.ndarray]:
    """A copy of ``graph`` in which false loops make up ``fraction`` of all loop closures, and
    their mask: half between nodes 2 to ``NEARBY`` ids apart, half between nodes at least
    ``NEARBY`` apart; each a random relative pose (uniform rotation, translation uniform within
    ± the extent of the graph's positions) with the information of a random loop of the graph
    (of a random edge where it has none). The graph must have values."""
    _check_fraction(fraction)
    rng = np.random.default_rng(seed)
    loops = ~odometry_mask(graph)
    count = int(round(fraction / (1.0 - fraction) * loops.sum()))
    n = graph.num_nodes
    nearby = count // 2
    i_near = rng.integers(0, n, size=nearby)
    j_near = i_near + rng.integers(2, NEARBY + 1, size=nearby) * rng.choice([-1, 1], size=nearby)
    i_near, j_near = i_near[(j_near >= 0) & (j_near < n)], j_near[(j_near >= 0) & (j_near < n)]
    i_far = rng.integers(0, n, size=8 * (count - i_near.size) + 16)
    j_far = rng.integers(0, n, size=i_far.size)
    far = np.abs(i_far - j_far) >= NEARBY
    distant = count - i_near.size
    i = np.concatenate([i_near, i_far[far][:distant]])
    j = np.concatenate([j_near, j_far[far][:distant]])
    positions = graph.values.translation
    extent = positions.max(axis=0) - positions.min(axis=0)
    measurements = _random_poses(graph.group, rng, i.size, -extent, extent)
    pool = np.flatnonzero(loops) if loops.any() else np.arange(graph.num_edges)
    information = graph.edges.information[rng.choice(pool, size=i.size)]
    return _with_false_edges(graph, i, j, measurements, information)


def _with_false_edges(
    graph: PoseGraph, i: np.ndarray, j: np.ndarray, measurements: LieGroup, information: np.ndarray
) -> tuple[PoseGraph, np.ndarray]:
    """A copy of ``graph`` with edges i → j (node indices) appended, and their mask."""
    corrupted = graph.copy()
    corrupted.add_edges(graph.node_ids[i], graph.node_ids[j], measurements, information)
    false_mask = np.zeros(corrupted.num_edges, dtype=bool)
    false_mask[graph.num_edges :] = True
    return corrupted, false_mask


def without_priors(graph: PoseGraph, false: np.ndarray) -> PoseGraph:
    """A copy of ``graph`` without the priors where ``false`` holds (the reference that robust
    estimation is measured against)."""
    clean = graph.copy()
    clean.priors = clean.priors.subset(~false)
    return clean


def _check_fraction(fraction: float) -> None:
    if not 0 <= fraction < 1:
        raise ValueError(f"the outlier fraction must be in [0, 1), not {fraction}")


def _random_poses(
    group: type[LieGroup], rng: np.random.Generator, count: int, low: np.ndarray, high: np.ndarray
) -> LieGroup:
    """``count`` poses of uniform rotation, their translation uniform between ``low`` and
    ``high``."""
    poses = group.sample(rng, (count,))
    return dataclasses.replace(
        poses, translation=rng.uniform(low, high, size=poses.translation.shape)
    )


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


def add_fixes(
    graph: PoseGraph,
    truth: LieGroup,
    every: int,
    information: np.ndarray,
    fraction: float,
    seed: int,
) -> tuple[PoseGraph, np.ndarray]:
    """A copy of ``graph`` with a prior on every ``every``-th node (from the first), measured as
    Z = X · Exp(n), n ~ N(0, Ω⁻¹), around the ``truth`` X, with the (d, d) ``information`` Ω;
    ``fraction`` of them, at random, are false (a random pose, its position uniform within the
    extent of the true positions). Also returns the mask of the false priors."""
    _check_fraction(fraction)
    rng = np.random.default_rng(seed)
    nodes = np.arange(0, graph.num_nodes, every)
    noise = rng.normal(size=(nodes.size, graph.group.dof)) @ information_root(
        information, inverse=True
    )
    measurements = truth[nodes].retract(noise)
    false = np.zeros(nodes.size, dtype=bool)
    false[rng.choice(nodes.size, size=int(round(fraction * nodes.size)), replace=False)] = True
    low, high = truth.translation.min(axis=0), truth.translation.max(axis=0)
    random_poses = _random_poses(graph.group, rng, int(false.sum()), low, high)
    measurements = measurements.set_at(np.flatnonzero(false), random_poses)
    fixed = graph.copy()
    first = len(fixed.priors)
    fixed.add_priors(
        graph.node_ids[nodes],
        measurements,
        np.broadcast_to(information, (nodes.size,) + information.shape),
    )
    false_mask = np.zeros(len(fixed.priors), dtype=bool)
    false_mask[first:] = false
    return fixed, false_mask
