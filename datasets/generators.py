"""Seeded generators of synthetic pose graphs with known ground truth.

* ``manhattan_world``: a planar robot driving on a unit grid (the M3500 benchmark's shape),
  with loop closures wherever it comes back to a cell it visited before.
* ``sphere``: poses on the surface of a sphere, ring after ring (the sphere2500 benchmark's
  shape), with loop closures between neighbouring rings.
* ``grid``: poses at the points of a cubic lattice, visited row by row (the shape of the
  tinyGrid3D and smallGrid3D benchmarks), with loop closures between lattice neighbours.

Both return the graph, with initial values from composing the noisy odometry, and the truth.
* ``visual_odometry``: a wandering SE2 or SE3 trajectory whose loop closures all reach a few
  poses back (a visual-odometry front end's), the stream a fixed-lag smoother takes.

``resimulate`` gives any graph a known ground truth: it keeps the graph's edges and information
and draws new measurements around chosen true poses. ``docked`` adds a node that every pose
measures: one dense row and column in an otherwise sparse problem.
Measurements are Z = (Xᵢ⁻¹ Xⱼ) · Exp(n), n ~ N(0, Σ), with information Σ⁻¹ (CONVENTIONS.md).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from posegraph.graph import PoseGraph
from posegraph.lie import SE2, SE3, LieGroup
from posegraph.lie.so3 import exp_matrix
from posegraph.problem.factors import information_root


def noisy_measurements(
    truth: LieGroup,
    i: np.ndarray,
    j: np.ndarray,
    information: np.ndarray,
    rng: np.random.Generator,
) -> LieGroup:
    """Z = (Xᵢ⁻¹ Xⱼ) · Exp(n) with n ~ N(0, Ω⁻¹) for each edge's (d, d) information Ω, full or
    diagonal: n = Ω^-½ z with z ~ N(0, I) (a diagonal Ω scales z by its σ in place); directions
    of zero information get no noise (an infinite variance cannot be drawn)."""
    z = rng.normal(size=(i.size, type(truth).dof))
    noise = np.einsum("mab,mb->ma", information_root(information, inverse=True), z)
    return truth[i].between(truth[j]).retract(noise)


def _noisy_graph(
    truth: LieGroup,
    i: np.ndarray,
    j: np.ndarray,
    sigmas: np.ndarray,
    rng: np.random.Generator,
) -> PoseGraph:
    """The graph of edges i → j measured with noise of standard deviations ``sigmas``,
    initialised by composing the noisy odometry edges (k → k+1), which must come first."""
    group = type(truth)
    information = np.broadcast_to(np.diag(1.0 / sigmas**2), (i.size, group.dof, group.dof))
    measurements = noisy_measurements(truth, i, j, information, rng)
    count = truth.batch_shape[0]
    initial = [truth[0]]
    for k in range(count - 1):  # the odometry edges are the first count − 1
        initial.append(initial[-1] @ measurements[k])
    graph = PoseGraph(group)
    graph.add_nodes(np.arange(count), group.stack(initial))
    graph.add_edges(i, j, measurements, information)
    return graph


def resimulate(graph: PoseGraph, truth: LieGroup, seed: int) -> PoseGraph:
    """A copy of ``graph`` whose between measurements are drawn anew around the poses ``truth``
    (one per node) with the noise the graph's own information matrices state, so that
    ``truth`` is its ground truth. Nodes, fixed nodes, priors and information are kept; the
    node values become ``truth``, marked as not optimised (an initialiser replaces them)."""
    rng = np.random.default_rng(seed)
    edges = graph.edges
    measurements = noisy_measurements(truth, edges.i, edges.j, edges.information, rng)
    simulated = graph.copy()
    simulated.edges = dataclasses.replace(edges, measurements=measurements)
    simulated.set_values(truth)
    return simulated


def manhattan_world(
    num_poses: int = 500,
    grid_size: int = 12,
    loop_probability: float = 0.5,
    translation_sigma: float = 0.05,
    rotation_sigma: float = 0.01,
    seed: int = 0,
) -> tuple[PoseGraph, SE2]:
    """A robot on a ``grid_size`` × ``grid_size`` unit grid: each step it goes straight (70%)
    or turns ±90° (15% each) and moves one cell; it turns back at the border. A later visit to
    an earlier pose's cell (more than 10 steps apart) adds that loop closure with probability
    ``loop_probability``."""
    rng = np.random.default_rng(seed)
    x, y, heading = 0, 0, 0
    cells, headings = [(x, y)], [heading]
    directions = [(1, 0), (0, 1), (-1, 0), (0, -1)]
    while len(cells) < num_poses:
        turn = rng.choice([0, 1, -1], p=[0.7, 0.15, 0.15])
        for candidate in (turn, -turn or 1, 2):
            h = (heading + candidate) % 4
            nx, ny = x + directions[h][0], y + directions[h][1]
            if 0 <= nx < grid_size and 0 <= ny < grid_size:
                heading, x, y = h, nx, ny
                break
        cells.append((x, y))
        headings.append(heading)
    cells_array = np.array(cells, dtype=float)
    truth = SE2(np.array(headings) * np.pi / 2, cells_array)
    loops_i, loops_j = [], []
    first_visit: dict[tuple[int, int], list[int]] = {}
    for k, cell in enumerate(cells):
        for earlier in first_visit.get(cell, []):
            if k - earlier > 10 and rng.random() < loop_probability:
                loops_i.append(earlier)
                loops_j.append(k)
        first_visit.setdefault(cell, []).append(k)
    i = np.concatenate([np.arange(num_poses - 1), loops_i]).astype(np.int64)
    j = np.concatenate([np.arange(1, num_poses), loops_j]).astype(np.int64)
    sigmas = np.array([translation_sigma, translation_sigma, rotation_sigma])
    return _noisy_graph(truth, i, j, sigmas, rng), truth


def sphere(
    rings: int = 10,
    poses_per_ring: int = 20,
    radius: float = 10.0,
    translation_sigma: float = 0.05,
    rotation_sigma: float = 0.01,
    seed: int = 0,
) -> tuple[PoseGraph, SE3]:
    """Poses on a sphere, ring by ring from bottom to top, each facing along its ring; every
    pose after the first ring closes a loop with the pose below it in the previous ring."""
    rng = np.random.default_rng(seed)
    count = rings * poses_per_ring
    ring = np.arange(count) // poses_per_ring
    azimuth = 2 * np.pi * (np.arange(count) % poses_per_ring) / poses_per_ring
    elevation = -np.pi / 2 + np.pi * (ring + 1) / (rings + 1)
    position = radius * np.stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ],
        axis=1,
    )
    yaw = exp_matrix(np.stack([np.zeros(count), np.zeros(count), azimuth + np.pi / 2], axis=1))
    pitch = exp_matrix(np.stack([-elevation, np.zeros(count), np.zeros(count)], axis=1))
    truth = SE3(yaw @ pitch, position)
    above = np.arange(poses_per_ring, count)
    i = np.concatenate([np.arange(count - 1), above - poses_per_ring])
    j = np.concatenate([np.arange(1, count), above])
    sigmas = np.array([translation_sigma] * 3 + [rotation_sigma] * 3)
    return _noisy_graph(truth, i, j, sigmas, rng), truth


def grid(
    size: int = 5,
    spacing: float = 1.0,
    translation_sigma: float = 0.05,
    rotation_sigma: float = 0.01,
    seed: int = 0,
) -> tuple[PoseGraph, SE3]:
    """``size``³ poses on a cubic lattice of ``spacing``, visited row by row, each row the other
    way than the last, each pose facing along +x; every pose after the first closes a loop with
    each lattice neighbour visited earlier that is not its predecessor."""
    rng = np.random.default_rng(seed)
    order = []
    for z in range(size):
        for y in range(size):
            row = [(x, y, z) for x in range(size)]
            order += row if (z * size + y) % 2 == 0 else row[::-1]
    points = np.array(order)
    count = len(order)
    index = {point: k for k, point in enumerate(order)}
    loops_i, loops_j = [], []
    for k, point in enumerate(order):
        for axis in range(3):
            neighbour = list(point)
            neighbour[axis] -= 1
            earlier = index.get(tuple(neighbour), count)
            if earlier < k - 1:
                loops_i.append(earlier)
                loops_j.append(k)
    truth = SE3(np.broadcast_to(np.eye(3), (count, 3, 3)).copy(), spacing * points.astype(float))
    i = np.concatenate([np.arange(count - 1), loops_i]).astype(np.int64)
    j = np.concatenate([np.arange(1, count), loops_j]).astype(np.int64)
    sigmas = np.array([translation_sigma] * 3 + [rotation_sigma] * 3)
    return _noisy_graph(truth, i, j, sigmas, rng), truth


def visual_odometry(
    group: type[LieGroup],
    poses: int = 200,
    reach: int = 8,
    loop_share: float = 0.35,
    translation_sigma: float = 0.05,
    rotation_sigma: float = 0.02,
    seed: int = 0,
) -> tuple[PoseGraph, LieGroup]:
    """``poses`` SE2 or SE3 poses moving about 1 m forward per step with random turns; odometry
    between consecutive poses and, from about ``loop_share`` of the poses, a loop closure to a
    pose 2 to ``reach`` − 1 steps back. Pose 0 has a prior at its true value (σ = 0.01)."""
    rng = np.random.default_rng(seed)
    d = group.dof
    rotation = 1 if group is SE2 else 3
    forward = np.zeros(d)
    forward[0] = 1.0
    spread = np.r_[0.1, np.full(d - rotation - 1, 0.05), np.full(rotation, 0.3)]
    motion = group.exp(forward + rng.normal(size=(poses - 1, d)) * spread)
    truth = [group.identity()]
    for step in motion:
        truth.append(truth[-1] @ step)
    truth = group.stack(truth)
    later = np.flatnonzero(rng.random(poses) < loop_share)
    later = later[later >= 3]
    back = rng.integers(2, np.minimum(later, reach - 1) + 1)
    i = np.concatenate([np.arange(poses - 1), later - back]).astype(np.int64)
    j = np.concatenate([np.arange(1, poses), later]).astype(np.int64)
    sigmas = np.r_[np.full(d - rotation, translation_sigma), np.full(rotation, rotation_sigma)]
    graph = _noisy_graph(truth, i, j, sigmas, rng)
    graph.add_prior(0, truth[0], np.eye(d) * 1e4)
    return graph, truth


def docked(
    graph: PoseGraph, truth: LieGroup, every: int = 1, seed: int = 0
) -> tuple[PoseGraph, LieGroup]:
    """A generated graph (edges only, ids 0 … n−1) with a docking station: a pose node put
    second, after the first pose, that every ``every``-th pose measures with the first edge's
    information. The dock stands for any node that thousands of edges reach (a second session's
    anchor, a place revisited all the time); being second, it is early in the elimination
    order. Returns the graph, whose dock starts where the first pose's measurement of it puts
    it, and the truth."""
    rng = np.random.default_rng(seed)
    group, n = graph.group, graph.num_nodes
    dock = truth[0] @ group.exp(np.full(group.dof, 0.5))
    moved = np.arange(n) + (np.arange(n) >= 1)  # old index → new, the dock taking index 1
    new_truth = group.concatenate([truth[:1], dock[None], truth[1:]])
    observers = moved[np.arange(0, n, every)]
    information = np.broadcast_to(graph.edges.information[0], (observers.size,) + (group.dof,) * 2)
    sightings = noisy_measurements(new_truth, observers, np.ones_like(observers), information, rng)
    docked_graph = PoseGraph(group)
    docked_graph.add_nodes(
        np.arange(n + 1),
        group.concatenate(
            [graph.values[:1], (graph.values[0] @ sightings[0])[None], graph.values[1:]]
        ),
    )
    docked_graph.add_edges(
        moved[graph.edges.i],
        moved[graph.edges.j],
        graph.edges.measurements,
        graph.edges.information,
    )
    docked_graph.add_edges(observers, np.ones_like(observers), sightings, information)
    return docked_graph, new_truth
