"""Trajectory files: KITTI blocks that are not rotations are refused naming their line, node
ids keep their 64 bits as trajectory keys, and EuRoC's ground truth reads as evo reads it."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph import PoseGraph
from posegraph.io import GraphFileError, write_graph
from posegraph.io.conversion import convert, load_trajectory
from posegraph.io.trajectories import read_trajectory
from posegraph.lie import SE2
from posegraph.trajectory.evaluation import evaluate

from ..cli.helpers import run

IDENTITY_ROW = "1 0 0 0 0 1 0 0 0 0 1 0"


def _kitti(tmp_path, third: str):
    path = tmp_path / "poses.txt"
    path.write_text(f"{IDENTITY_ROW}\n# a comment\n{IDENTITY_ROW}\n{third}\n")
    return path


def test_a_kitti_reflection_is_refused_naming_its_line(tmp_path):
    """diag(1, 1, −1) is orthogonal: projected to the nearest rotation it read as the identity,
    and ``eval`` reported an ATE of 0."""
    path = _kitti(tmp_path, "1 0 0 0 0 1 0 0 0 0 -1 0")
    with pytest.raises(GraphFileError, match=r"is a reflection \(determinant -1\)") as raised:
        read_trajectory(str(path), "kitti")
    assert raised.value.line == 4


def test_a_kitti_block_off_the_rotations_names_its_line(tmp_path):
    path = _kitti(tmp_path, "1 0 0 0 0 2 0 0 0 0 1 0")
    with pytest.raises(GraphFileError, match="is not a rotation matrix") as raised:
        read_trajectory(str(path), "kitti")
    assert raised.value.line == 4


def _graph_with_large_ids() -> PoseGraph:
    """Three poses whose ids differ beyond 2⁵³ only in their last digits."""
    ids = [2**60, 2**60 + 1, 2**60 + 2]
    graph = PoseGraph(SE2)
    graph.add_nodes(ids, SE2.from_xytheta(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0.5, 0]])))
    graph.add_edges(ids[:2], ids[1:], SE2.from_xytheta(np.array([[1.0, 0, 0]] * 2)), np.eye(3))
    return graph


def test_node_ids_beyond_2_53_stay_apart_as_trajectory_keys(tmp_path):
    """``eval g.g2o g.g2o`` paired 2 of 3 poses: float keys merged two ids."""
    path = tmp_path / "large_ids.g2o"
    write_graph(_graph_with_large_ids(), str(path))
    trajectory = load_trajectory(str(path))
    assert trajectory.keys.tolist() == [2**60, 2**60 + 1, 2**60 + 2]
    assert evaluate(trajectory, trajectory, "se3").matched == 3
    assert run("eval", path, path).returncode == 0


def test_a_tum_time_stamp_that_cannot_hold_an_id_is_refused(tmp_path):
    """``convert`` to TUM wrote two ids as the same time stamp with exit 0."""
    graph = _graph_with_large_ids()
    path = tmp_path / "large_ids.tum"
    with pytest.raises(ValueError, match=r"node id 1152921504606846977 is beyond 2⁵³"):
        convert(graph, str(path))
    assert not path.exists()
    convert(graph, str(tmp_path / "large_ids.kitti"))  # KITTI has no keys to lose
    assert read_trajectory(str(tmp_path / "large_ids.kitti"), "kitti").keys.size == 3


def test_euroc_ground_truth_reads_its_first_eight_columns(tmp_path):
    """EuRoC's state_groundtruth_estimate0/data.csv: a header, time stamps in ns, position, then
    the quaternion w first; further columns (velocity, biases) are ignored."""
    path = tmp_path / "data.csv"
    path.write_text(
        "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [],"
        " q_RS_z [], v_RS_R_x [m s^-1]\n"
        "1403636579758555392,4.688,-1.786,0.783,0.534,-0.153,-0.827,-0.082,0.1\n"
        "1403636579763555584,4.689,-1.786,0.788,0.534,-0.153,-0.827,-0.082,0.1\n"
    )
    trajectory = read_trajectory(str(path), "euroc")
    np.testing.assert_allclose(trajectory.keys, [1403636579.758555392, 1403636579.763555584])
    np.testing.assert_allclose(trajectory.positions[1], [4.689, -1.786, 0.788])
    q, _ = trajectory.poses[:1].as_quaternion_translation()
    expected = np.array([-0.153, -0.827, -0.082, 0.534])
    np.testing.assert_allclose(
        np.abs(q[0]), np.abs(expected / np.linalg.norm(expected)), atol=1e-12
    )
    path.write_text("1403636579758555392,4.688,-1.786\n")
    with pytest.raises(GraphFileError, match=r"data.csv:1: EuRoC lines have at least 8"):
        read_trajectory(str(path), "euroc")
