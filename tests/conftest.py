"""Fixtures shared by the test suite: benchmark graphs and small generated graphs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.outliers import add_fixes
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

import posegraph
from posegraph.graph import PoseGraph
from posegraph.lie import SE2, SE3, LieGroup, Sim3
from posegraph.lie.uncertainty import compose_covariance


@pytest.fixture(scope="session")
def shared_dataset():
    """Path to a graph of ../shared/datasets; skips the test when that folder is absent."""
    folder = shared_datasets_dir()

    def find(name: str) -> Path:
        if folder is None:
            pytest.skip("../shared/datasets is not beside this checkout (benchmark graphs needed)")
        return folder / name

    return find


@pytest.fixture(scope="session")
def gtsam_dataset():
    """Path to a file of the gtsam wheel's Data/ folder; skips when gtsam is not installed."""
    folder = gtsam_data_dir()

    def find(name: str) -> Path:
        if folder is None or not (folder / name).is_file():
            pytest.skip(f"gtsam's Data/{name} is not available (install the test extra)")
        return folder / name

    return find


def random_graph(
    group: type[LieGroup],
    num_nodes: int,
    num_loops: int,
    seed: int,
    noise: float = 0.05,
    priors: int = 0,
) -> PoseGraph:
    """A chain of ``num_nodes`` poses with ``num_loops`` extra edges, noisy measurements,
    random SPD information, and initial values perturbed from the truth."""
    rng = np.random.default_rng(seed)
    truth = group.exp(0.5 * rng.normal(size=(num_nodes, group.dof)))
    ids = np.arange(num_nodes) * 2 + 10  # non-contiguous ids
    i = np.concatenate([np.arange(num_nodes - 1), rng.integers(0, num_nodes, num_loops)])
    j = np.concatenate([np.arange(1, num_nodes), rng.integers(0, num_nodes, num_loops)])
    keep = i != j
    i, j = i[keep], j[keep]
    d = group.dof
    measured = truth[i].between(truth[j]).retract(noise * rng.normal(size=(i.size, d)))
    a = rng.normal(size=(i.size, d, d))
    information = a @ np.swapaxes(a, 1, 2) + d * np.eye(d)
    graph = PoseGraph(group)
    graph.add_nodes(ids, truth.retract(noise * rng.normal(size=(num_nodes, d))))
    graph.add_edges(ids[i], ids[j], measured, information)
    if priors:
        nodes = rng.choice(num_nodes, priors, replace=False)
        graph.add_priors(ids[nodes], truth[nodes], np.eye(d) * 10.0)
    return graph


def union(first: PoseGraph, second: PoseGraph, id_offset: int) -> PoseGraph:
    """One graph holding both graphs as separate components (the second's ids shifted)."""
    graph = PoseGraph(first.group)
    for part, offset in ((first, 0), (second, id_offset)):
        ids = part.node_ids + offset
        graph.add_nodes(ids, part.values)
        graph.add_edges(
            ids[part.edges.i], ids[part.edges.j], part.edges.measurements, part.edges.information
        )
    return graph


def cull(smoother: posegraph.Smoother, node_id: int) -> None:
    """Remove a keyframe of a chain of ids from a smoother's graph, re-linking its neighbours by
    the composition of the edges (k − 1 → k, k → k + 1) through it, its covariance by Eade
    §8.2."""
    graph = smoother.graph
    ids, edges = graph.node_ids, graph.edges
    starts, ends = ids[edges.i], ids[edges.j]
    into = np.flatnonzero((starts == node_id - 1) & (ends == node_id))[0]
    out = np.flatnonzero((starts == node_id) & (ends == node_id + 1))[0]
    z_into, z_out = edges.measurements[into], edges.measurements[out]
    covariance = compose_covariance(
        z_into,
        np.linalg.inv(edges.information[into]),
        z_out,
        np.linalg.inv(edges.information[out]),
    )
    graph.add_edge(node_id - 1, node_id + 1, z_into @ z_out, np.linalg.inv(covariance))
    smoother.remove_nodes([node_id])


SCALE_STEP = Sim3.exp(np.array([0, 0, 0, 0, 0, 0, 100.0]))
"""A Sim3 measurement that multiplies the scale by e^100, the largest scale an element may
have (``posegraph.graph.checks.LOG_DETERMINANT_LIMIT``)."""


def sim3_scale_chain(with_values: bool = True) -> PoseGraph:
    """Nodes 0–10 joined by edges i → i+1 of ``SCALE_STEP``: composed from node 0, node 8 lies
    at scale e^800 and node 10 at e^1000, beyond double precision (which ends near e^709).
    ``with_values``: every node at the identity; else none has a value."""
    graph = PoseGraph(Sim3)
    graph.add_nodes(np.arange(11), Sim3.identity((11,)) if with_values else None)
    graph.add_edges(np.arange(10), np.arange(1, 11), SCALE_STEP, np.eye(7))
    return graph


def maps_joined_by_positions(group: type[LieGroup], joins: int) -> PoseGraph:
    """Two maps of 20 poses (ids 10–48 and 1010–1048), optimised, joined by ``joins``
    position-only edges (σ = 0.1 m) from nodes 16, 30, 40 of the first to 1018, 1034, 1012 of
    the second."""
    first, second = (random_graph(group, 20, 6, seed=seed, noise=0.02) for seed in (72, 73))
    graph = union(first, second, 1000)
    rng = np.random.default_rng(74)
    dof, d = group.dof, group.point_dim
    information = np.diag(np.where(np.arange(dof) < d, 100.0, 0.0))
    for i, j in [(16, 1018), (30, 1034), (40, 1012)][:joins]:
        a, b = graph.index([i, j])
        measurement = graph.values[a].between(graph.values[b]).retract(0.05 * rng.normal(size=dof))
        graph.add_edges([i], [j], measurement[None], information[None])
    posegraph.optimize(graph)
    return graph


POSE_GROUPS = [SE2, SE3, Sim3]


def gnss_track(group: type[LieGroup], heading: float, seed: int) -> tuple[PoseGraph, LieGroup]:
    """200 poses driving a gentle S-curve that starts at UTM-like coordinates facing
    ``heading``, with odometry and a position-only prior (σ = 1 m, no rotation information)
    every 20 poses: GNSS fused with odometry, a tree with no loop closure."""
    rng = np.random.default_rng(seed)
    d = group.point_dim
    start = np.eye(d + 1)
    start[:2, :2] = [[np.cos(heading), -np.sin(heading)], [np.sin(heading), np.cos(heading)]]
    start[:d, d] = [500000.0, 4000000.0, 100.0][:d]
    steps = np.zeros((199, group.dof))
    steps[:, 0] = 1.0  # forward, turning by a yaw (θ of SE2, φ_z of SE3) that swings
    steps[:, 2 if group is SE2 else 5] = 0.02 * np.sin(np.arange(1, 200) / 10)
    truth = [group.from_matrix(start)]
    for step in group.exp(steps):
        truth.append(truth[-1] @ step)
    truth = group.concatenate([t.broadcast_to((1,)) for t in truth])
    graph = PoseGraph(group)
    graph.add_nodes(np.arange(200))
    odometry = truth[:-1].between(truth[1:]).retract(rng.normal(scale=0.01, size=(199, group.dof)))
    graph.add_edges(np.arange(199), np.arange(1, 200), odometry, np.eye(group.dof) * 100.0)
    gnss = np.arange(0, 200, 20)
    fixes = np.tile(np.eye(d + 1), (gnss.size, 1, 1))
    fixes[:, :d, d] = truth.translation[gnss] + rng.normal(scale=1.0, size=(gnss.size, d))
    information = np.zeros((group.dof, group.dof))
    information[:d, :d] = np.eye(d)
    graph.add_priors(gnss, fixes, information)
    return graph, truth


def city_with_fixes(fraction: float, seed: int) -> tuple[PoseGraph, np.ndarray]:
    """A generated city with a pose fix (σ 0.5 m, 0.1 rad) on every 5th node, ``fraction`` of
    them false, and the mask of the false ones."""
    graph, truth = manhattan_world(num_poses=300, seed=67)
    return add_fixes(graph, truth, 5, np.diag([4.0, 4.0, 100.0]), fraction, seed)
