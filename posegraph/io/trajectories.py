"""Trajectory files: TUM (``t tx ty tz qx qy qz qw``), KITTI (3 × 4 row-major [R | t]) and,
read only, EuRoC's ground-truth CSV (``timestamp [ns], px, py, pz, qw, qx, qy, qz, …``, as
evo's ``euroc`` reader takes its first eight columns).

A trajectory is a pair (keys, SE3 poses). For TUM the key is the time stamp column; a pose
graph's export writes node ids there. KITTI lines have no key: the line index is the key.
EuRoC's time stamps, in nanoseconds, become seconds.
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..lie import SE2, SE3, LieGroup, Sim3
from .atomic import atomic_write_text
from .errors import GraphFileError
from .parsing import code_lines, paused_garbage_collection, quaternion_problems, read_lines
from .writer import number_fields, refuse_non_finite, written_finite

if TYPE_CHECKING:
    from ..graph import PoseGraph


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Stamped poses: ``keys`` (N,) and ``poses`` (SE3, batch (N,)). Keys are time stamps
    (float) or a graph's node ids (int64, exact beyond 2⁵³)."""

    keys: np.ndarray
    poses: SE3

    @classmethod
    def of_graph(cls, graph: PoseGraph, values: LieGroup | None = None) -> Trajectory:
        """A graph's poses (``values``, by default its own) keyed by node id, as SE3
        (``as_se3``)."""
        return cls(graph.node_ids.copy(), as_se3(graph.values if values is None else values))

    @property
    def positions(self) -> np.ndarray:
        return self.poses.translation


def as_se3(values: LieGroup) -> SE3:
    """SE3 poses of any pose group: SE2 lifted to the plane z = 0; Sim3 keeps R and t."""
    if isinstance(values, SE3):
        return values
    if isinstance(values, SE2):
        count = values.batch_shape[0]
        rotation = np.zeros((count, 3, 3))
        rotation[:, :2, :2] = values.rotation_matrix
        rotation[:, 2, 2] = 1.0
        translation = np.concatenate([values.translation, np.zeros((count, 1))], axis=1)
        return SE3(rotation, translation)
    if isinstance(values, Sim3):
        return SE3(values.rotation, values.translation)
    raise TypeError(f"no SE3 trajectory for {type(values).__name__}")


def _text(rows: np.ndarray) -> str:
    return "".join(" ".join(fields) + "\n" for fields in number_fields(rows))


@paused_garbage_collection()
def format_tum(trajectory: Trajectory) -> str:
    q, t = trajectory.poses.as_quaternion_translation()
    rows = np.concatenate([trajectory.keys[:, None].astype(float), t, q], axis=1)
    return _text(rows)


@paused_garbage_collection()
def format_kitti(trajectory: Trajectory) -> str:
    rows = trajectory.poses.as_matrix()[:, :3, :].reshape(-1, 12)
    return _text(rows)


def write_trajectory(trajectory: Trajectory, path: str, file_format: str) -> None:
    """Write "tum" or "kitti" atomically. Integer keys (node ids) that a TUM time stamp, a
    double, cannot hold exactly (some beyond 2⁵³) are refused."""
    refuse_non_finite(path, trajectory.keys, trajectory.poses)
    keys = trajectory.keys
    if file_format == "tum" and keys.dtype.kind in "iu":
        inexact = [key for key in keys[np.abs(keys) > 2**53].tolist() if int(float(key)) != key]
        if inexact:
            raise ValueError(
                f"{path}: node id {inexact[0]} is beyond 2⁵³, where a TUM time stamp (a double)"
                " cannot hold it exactly; write a graph file (g2o) instead"
            )
    with written_finite(path):
        text = {"tum": format_tum, "kitti": format_kitti}[file_format](trajectory)
    atomic_write_text(path, text)


def _numbers(path: str, lines: list, width: int, name: str) -> np.ndarray:
    """The (n, ``width``) numbers of a trajectory file's lines: converted at once, or where that
    fails, line by line, naming the first bad line."""
    if all(len(tokens) == width for _, tokens in lines):
        with contextlib.suppress(ValueError):
            numbers = np.array([tokens for _, tokens in lines], dtype=float)
            if np.isfinite(numbers).all():
                return numbers
    rows = []
    for number, tokens in lines:
        if len(tokens) != width:
            raise GraphFileError(
                path, number, f"{name} lines have {width} numbers, found {len(tokens)}"
            )
        try:
            row = np.array(tokens, dtype=float)
        except ValueError:
            raise GraphFileError(path, number, "a value is not a number") from None
        if not np.all(np.isfinite(row)):
            raise GraphFileError(path, number, "NaN or infinite value")
        rows.append(row)
    return np.array(rows)


ROTATION_TOLERANCE = 1e-3
"""Largest |R Rᵀ − I| entry of a KITTI line's 3 × 3 block read as a rotation (the files hold
about six digits); the block is then projected to the nearest rotation."""


def _refuse_non_rotations(path: str, lines: list, rotation: np.ndarray) -> None:
    """Raise naming the first KITTI line whose 3 × 3 block is not a rotation: not orthogonal,
    or a reflection (determinant −1), which a projection would silently turn into a rotation."""
    with np.errstate(all="ignore"):
        error = np.abs(rotation @ np.swapaxes(rotation, 1, 2) - np.eye(3)).max(axis=(1, 2))
        determinant = np.linalg.det(rotation)
    bad = ~(error <= ROTATION_TOLERANCE) | ~(determinant > 0)
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[0])
    why = (
        f"is a reflection (determinant {determinant[k]:.3g}), not a rotation"
        if error[k] <= ROTATION_TOLERANCE
        else f"is not a rotation matrix (|R Rᵀ − I| reaches {error[k]:.3g})"
    )
    raise GraphFileError(path, lines[k][0], f"the 3 × 3 block {why}")


def _euroc_lines(path: str) -> list[tuple[int, list[str]]]:
    """(line number, its first eight comma-separated fields) of a EuRoC CSV's data lines."""
    lines = []
    for number, code in code_lines(path):
        fields = [field.strip() for field in code.split(",")]
        if len(fields) < 8:
            raise GraphFileError(
                path,
                number,
                f"EuRoC lines have at least 8 comma-separated values, found {len(fields)}",
            )
        lines.append((number, fields[:8]))
    return lines


def _stamped(
    path: str, lines: list, stamps: np.ndarray, q: np.ndarray, t: np.ndarray
) -> Trajectory:
    """Time-stamped poses from quaternions (x, y, z, w) and translations; raise naming the first
    line whose quaternion is not a rotation."""
    problems = quaternion_problems(q)
    if problems:
        first = min(problems)
        raise GraphFileError(path, lines[first][0], problems[first])
    return Trajectory(stamps, SE3.from_quaternion_translation(q, t))


def read_trajectory(path: str, file_format: str) -> Trajectory:
    """Read "tum", "kitti" or "euroc"; errors name ``file:line``."""
    lines = _euroc_lines(path) if file_format == "euroc" else read_lines(path)
    width = {"tum": 8, "kitti": 12, "euroc": 8}[file_format]
    name = {"tum": "TUM", "kitti": "KITTI", "euroc": "EuRoC"}[file_format]
    if not lines:
        raise GraphFileError(path, None, f"holds no {name} poses")
    numbers = _numbers(path, lines, width, name)
    if file_format == "tum":
        return _stamped(path, lines, numbers[:, 0], numbers[:, 4:8], numbers[:, 1:4])
    if file_format == "euroc":
        q = numbers[:, [5, 6, 7, 4]]  # (w, x, y, z) → (x, y, z, w)
        return _stamped(path, lines, numbers[:, 0] * 1e-9, q, numbers[:, 1:4])
    matrices = numbers.reshape(-1, 3, 4)
    rotation = matrices[:, :, :3]
    _refuse_non_rotations(path, lines, rotation)
    return Trajectory(
        np.arange(len(numbers), dtype=float), SE3(rotation, matrices[:, :, 3]).normalize()
    )
