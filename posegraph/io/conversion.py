"""File-format choice for conversion and evaluation: graphs (g2o, TORO) and trajectories
(TUM, KITTI, and EuRoC's CSV to read), told apart by suffix, or for ``.txt`` by the number of
columns."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..graph import PoseGraph
from ..lie import LieGroup
from .errors import GraphFileError
from .load import load_graph
from .parsing import read_lines
from .reader import ReadResult
from .trajectories import Trajectory, read_trajectory, write_trajectory
from .writer import GRAPH_SUFFIXES, Rejected, unwritable, write_graph

SUFFIX_FORMATS = {**GRAPH_SUFFIXES, ".tum": "tum", ".kitti": "kitti"}
INPUT_SUFFIX_FORMATS = {**SUFFIX_FORMATS, ".csv": "euroc"}
GRAPH_FORMATS = ("g2o", "toro")
TRAJECTORY_FORMATS = ("tum", "kitti")
"""The trajectory formats written; ``euroc`` is read too."""


def output_format(path: str, requested: str | None = None) -> str:
    """The format to write ``path`` in: ``requested``, or by suffix."""
    if requested is not None:
        return requested
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIX_FORMATS:
        known = ", ".join(SUFFIX_FORMATS)
        raise ValueError(
            f"{path}: cannot tell the output format from {suffix or 'no suffix'!r} (known: {known})"
        )
    return SUFFIX_FORMATS[suffix]


def input_format(path: str) -> str:
    """g2o/TORO by their tags, TUM/KITTI/EuRoC by suffix (``.csv``: EuRoC) or, for other
    suffixes, by column count."""
    suffix = Path(path).suffix.lower()
    if suffix in INPUT_SUFFIX_FORMATS:
        return INPUT_SUFFIX_FORMATS[suffix]
    lines = read_lines(path)
    if not lines:
        raise GraphFileError(path, None, "holds no poses")
    first = lines[0][1]
    if first[0].isalpha() or first[0].startswith("_"):
        return "g2o"  # a tagged graph file (g2o or TORO, the reader tells them apart)
    if len(first) in (8, 12):
        return "tum" if len(first) == 8 else "kitti"
    raise GraphFileError(path, lines[0][0], "not a graph, TUM (8 columns) or KITTI (12) line")


def unwritable_to(
    graph: PoseGraph, path: str, to: str | None = None, group: type[LieGroup] | None = None
) -> str | None:
    """Why ``convert`` cannot write ``graph`` (or the graph lifted to ``group``) to ``path``,
    or None if it can (``posegraph.io.unwritable``: every graph has a trajectory)."""
    file_format = output_format(path, to)
    return unwritable(graph, file_format, group) if file_format in GRAPH_FORMATS else None


def convert(
    graph: PoseGraph,
    path: str,
    to: str | None = None,
    sim3_dialect: str = "a",
    g2o_rotation_information: bool = False,
    rejected: Rejected | None = None,
) -> str:
    """Write ``graph`` to ``path`` as a graph (its ``rejected`` measurements marked) or as its
    poses' trajectory; returns the format."""
    file_format = output_format(path, to)
    if file_format in GRAPH_FORMATS:
        write_graph(graph, path, file_format, g2o_rotation_information, sim3_dialect, rejected)
    else:
        write_trajectory(Trajectory.of_graph(graph), path, file_format)
    return file_format


def load_trajectory(path: str, read: Callable[[str], ReadResult] = load_graph) -> Trajectory:
    """Poses of any supported file: a trajectory, or the node values, keyed by id, of a graph
    file read by ``read`` (path → ``ReadResult``; its options and its record of what was
    skipped are the caller's)."""
    file_format = input_format(path)
    if file_format in GRAPH_FORMATS:
        return Trajectory.of_graph(read(path).graph)
    return read_trajectory(path, file_format)


def is_trajectory_file(path: str) -> bool:
    """Whether ``path`` holds a trajectory (TUM, KITTI, EuRoC) rather than a graph."""
    return input_format(path) not in GRAPH_FORMATS
