"""A monocular visual-odometry sequence with scale drift and Sim3 loop closures.

Ground truth: a camera driving 1.5 times around a 40 m × 20 m block (so it revisits the start),
facing its direction of travel, with a gentle height wave; poses T_w_c (world-from-camera).

Keyframe k's local map has scale s_k relative to the world, with log s_k − log s_{k−1} = ±log(1 +
drift): the scale compounds by ``drift`` per keyframe in one direction, which flips with
probability ``flip_probability`` per keyframe (0: monotone drift). The monocular system
measures its odometry k−1 → k in the units of frame k−1's map (translation times s_{k−1}) and
believes consecutive maps share one scale. A loop closure j → k is measured by aligning the two
local maps: the true relative similarity (X*_j)⁻¹ X*_k with X*_i = (R_i, t_i, 1/s_i), so it carries
the relative scale s_j / s_k. Noise is added on the right, Z·Exp(n), in the tangent of
CONVENTIONS.md.

``write_sequence`` writes a g2o file of SE3 odometry (its VERTEX_SE3:QUAT lines hold the drifted
dead-reckoning estimate) with EDGE_SIM3:EXPMAP loops, and the ground truth as TUM.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from posegraph.graph import PoseGraph
from posegraph.io.atomic import atomic_write_text
from posegraph.io.trajectories import Trajectory, write_trajectory
from posegraph.io.writer import format_g2o, sim3_edge_lines
from posegraph.lie import SE3, Sim3
from posegraph.lie.so3 import exp_matrix
from posegraph.sim3.scale_drift import add_sim3_loops
from posegraph.trajectory.evaluation import evaluate

from .outliers import add_false_loops


@dataclasses.dataclass(frozen=True)
class MonocularSequence:
    odometry: PoseGraph
    """SE3 graph: dead-reckoning values and the odometry edges k−1 → k."""
    loop_i: np.ndarray
    loop_j: np.ndarray
    loop_measurements: Sim3
    loop_information: np.ndarray
    truth: SE3
    """Ground-truth world-from-camera poses."""

    def sim3_graph(self, scale_information: float | None = None) -> PoseGraph:
        """The odometry lifted to Sim3, with the Sim3 loop closures."""
        ids = self.odometry.node_ids
        return add_sim3_loops(
            self.odometry,
            ids[self.loop_i],
            ids[self.loop_j],
            self.loop_measurements,
            self.loop_information,
            scale_information,
        )

    def sim3_graph_with_false_loops(
        self, fraction: float, seed: int, scale_information: float | None = None
    ) -> tuple[PoseGraph, np.ndarray]:
        """``sim3_graph`` with false loops making up ``fraction`` of its loop closures
        (``add_false_loops``), lifted as a file holding them all is read: the default lift hears
        the false loops' scales too. Returns the graph and the mask of the false edges."""
        corrupted, false = add_false_loops(self.sim3_graph(scale_information), fraction, seed)
        loops = np.arange(self.odometry.num_edges, corrupted.num_edges)
        ids, edges = corrupted.node_ids, corrupted.edges
        graph = add_sim3_loops(
            self.odometry,
            ids[edges.i[loops]],
            ids[edges.j[loops]],
            edges.measurements[loops],
            edges.information[loops],
            scale_information,
        )
        return graph, false

    def ate(self, poses: SE3) -> float:
        """ATE RMSE of world-from-camera ``poses`` against the ground truth, SE3-aligned (no
        scale fitting)."""
        estimate, truth = (Trajectory.of_graph(self.odometry, p) for p in (poses, self.truth))
        return evaluate(estimate, truth, "se3").ate.rmse

    def se3_graph(self) -> PoseGraph:
        """The odometry and the loops as SE3 (rotation and translation, scale dropped): what an
        SE3-only pose-graph optimisation would use."""
        graph = self.odometry.copy()
        ids = graph.node_ids
        z = self.loop_measurements
        graph.add_edges(
            ids[self.loop_i],
            ids[self.loop_j],
            SE3(z.rotation, z.translation),
            self.loop_information[:, :6, :6],
        )
        return graph


def _around_the_block(num_poses: int, width: float, height: float) -> SE3:
    perimeter = 2 * (width + height)
    travelled = np.linspace(0.0, 1.5 * perimeter, num_poses) % perimeter
    corners = np.array([[0, 0], [width, 0], [width, height], [0, height], [0, 0]], float)
    at_corner = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(corners, axis=0), axis=1))])
    x = np.interp(travelled, at_corner, corners[:, 0])
    y = np.interp(travelled, at_corner, corners[:, 1])
    z = 0.5 * np.sin(np.linspace(0.0, 6 * np.pi, num_poses))
    direction = np.diff(np.stack([x, y], axis=1), axis=0)
    direction = np.vstack([direction, direction[-1:]])
    heading = np.arctan2(direction[:, 1], direction[:, 0])
    yaw = exp_matrix(heading[:, None] * np.array([0.0, 0.0, 1.0]))
    return SE3(yaw, np.stack([x, y, z], axis=1))


def monocular_sequence(
    num_poses: int = 300,
    drift: float = 0.01,
    loop_distance: float = 1.5,
    min_loop_separation: int = 30,
    loop_stride: int = 5,
    translation_sigma: float = 0.02,
    rotation_sigma: float = 0.002,
    scale_sigma: float = 0.01,
    flip_probability: float = 0.0,
    seed: int = 0,
) -> MonocularSequence:
    """A seeded sequence (module docstring); ``drift`` is the relative scale change per keyframe.

    Every ``loop_stride``-th keyframe closes a loop with the nearest keyframe at least
    ``min_loop_separation`` earlier, if that one is within ``loop_distance`` metres.
    """
    rng = np.random.default_rng(seed)
    truth = _around_the_block(num_poses, 40.0, 20.0)
    direction = np.cumprod(np.where(rng.random(num_poses - 1) < flip_probability, -1.0, 1.0))
    scale = np.exp(np.concatenate([[0.0], np.cumsum(direction * np.log1p(drift))]))
    true_nodes = Sim3(truth.rotation, truth.translation, 1.0 / scale)

    k = np.arange(1, num_poses)
    relative = true_nodes[k - 1].between(true_nodes[k])
    noise = np.concatenate(
        [
            rng.normal(scale=translation_sigma, size=(k.size, 3)),
            rng.normal(scale=rotation_sigma, size=(k.size, 3)),
        ],
        axis=1,
    )
    odometry_measured = SE3(relative.rotation, relative.translation).retract(noise)
    dead_reckoning = [truth[0]]
    for step in range(k.size):
        dead_reckoning.append(dead_reckoning[-1] @ odometry_measured[step])
    odometry = PoseGraph(SE3)
    odometry.add_nodes(np.arange(num_poses), SE3.stack(dead_reckoning))
    odometry.add_edges(
        k - 1, k, odometry_measured, np.diag([translation_sigma**-2] * 3 + [rotation_sigma**-2] * 3)
    )

    loops_i, loops_j = [], []
    for later in range(min_loop_separation, num_poses, loop_stride):
        earlier = np.arange(later - min_loop_separation + 1)
        gap = np.linalg.norm(truth.translation[earlier] - truth.translation[later], axis=1)
        if gap.min() < loop_distance:
            loops_i.append(int(earlier[np.argmin(gap)]))
            loops_j.append(later)
    loop_i, loop_j = np.array(loops_i, dtype=np.int64), np.array(loops_j, dtype=np.int64)
    sigmas = np.array([translation_sigma] * 3 + [rotation_sigma] * 3 + [scale_sigma])
    loop_measurements = (
        true_nodes[loop_i]
        .between(true_nodes[loop_j])
        .retract(rng.normal(size=(loop_i.size, 7)) * sigmas)
    )
    loop_information = np.broadcast_to(np.diag(sigmas**-2), (loop_i.size, 7, 7)).copy()
    return MonocularSequence(odometry, loop_i, loop_j, loop_measurements, loop_information, truth)


def write_sequence(
    sequence: MonocularSequence,
    graph_path: str,
    truth_path: str | None,
    dialect: str = "a",
    truth_format: str = "tum",
) -> None:
    """The g2o file (SE3 odometry with EDGE_SIM3 loops) and, unless ``truth_path`` is None, the
    ground truth as ``truth_format`` ("tum" or "kitti")."""
    ids = sequence.odometry.node_ids
    loops = sim3_edge_lines(
        ids[sequence.loop_i],
        ids[sequence.loop_j],
        sequence.loop_measurements,
        sequence.loop_information,
        dialect,
    )
    atomic_write_text(graph_path, format_g2o(sequence.odometry) + "\n".join(loops) + "\n")
    if truth_path is not None:
        truth = Trajectory.of_graph(sequence.odometry, sequence.truth)
        write_trajectory(truth, truth_path, truth_format)


def main(arguments: list[str] | None = None) -> None:
    """``python -m posegraph_datasets.monocular GRAPH TRUTH [--drift D] [--seed S]``: write a
    sequence's g2o file and its ground truth (TUM), as ``posegraph scale-drift`` reads them."""
    import argparse

    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("graph", help="the g2o file to write (SE3 odometry, Sim3 loops)")
    parser.add_argument("truth", help="the ground truth to write (TUM)")
    parser.add_argument("--drift", type=float, default=0.01, help="scale change per keyframe")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(arguments)
    write_sequence(monocular_sequence(drift=args.drift, seed=args.seed), args.graph, args.truth)
    print(f"wrote {args.graph} and {args.truth}")


if __name__ == "__main__":
    main()
