"""Write a ``PoseGraph`` as g2o or TORO text, atomically, with round-trip-exact numbers."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..graph import PoseGraph
from ..lie import SE2, SE3, LieGroup, Sim3
from .atomic import atomic_write_text
from .parsing import REJECTED_PREFIX, paused_garbage_collection, upper_from_symmetric
from .tags import (
    matrix_to_rpy,
    se3_information_to_file,
    sim3_information_to_file,
    sim3_to_g2o_tangent,
    toro2_information_to_file,
)

GRAPH_SUFFIXES = {".g2o": "g2o", ".graph": "toro", ".toro": "toro"}
"""The graph format each file suffix names."""


class NonFiniteNumber(ValueError):
    """A number to be written is NaN or infinite; no reader accepts it, ours included."""


def number_fields(numbers: np.ndarray) -> list[list[str]]:
    """The text of each row's numbers: repr, which round-trips exactly, with −0.0 as 0.0.
    Raises ``NonFiniteNumber`` if one is NaN or infinite: every writer formats through here,
    so what it checks is what would be written."""
    numbers = np.asarray(numbers, float)
    finite = np.isfinite(numbers).all(axis=tuple(range(1, numbers.ndim)))
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise NonFiniteNumber(
            f"{np.count_nonzero(~finite)} line(s) would hold NaN or ∞ (the first: line {row + 1}"
            " of its kind)"
        )
    return [[repr(x) for x in row] for row in (numbers + 0.0).tolist()]


@contextlib.contextmanager
def written_finite(path: str) -> Iterator[None]:
    """Report a ``NonFiniteNumber`` met while formatting the text of ``path`` as not written
    (numpy's overflow warnings are silenced: the check finds what overflowed)."""
    try:
        with np.errstate(all="ignore"):
            yield
    except NonFiniteNumber as error:
        raise ValueError(f"{path}: not written: {error}") from None


def refuse_non_finite(path: str, keys: np.ndarray, values: LieGroup) -> None:
    """Raise before anything is written to ``path`` if a pose is not finite (an optimisation that
    diverged): no reader accepts NaN or ∞, ours included."""
    bad = np.flatnonzero(~np.isfinite(values.as_matrix()).all(axis=(-2, -1)))
    if bad.size:
        raise ValueError(
            f"{path}: not written: {bad.size} of {len(keys)} poses are not finite (the first"
            f" is {keys[bad[0]].tolist()})"
        )


def _lines(tag: str, ids: list[np.ndarray], numbers: np.ndarray) -> list[str]:
    """``TAG id… number…`` lines."""
    id_columns = [np.asarray(c).tolist() for c in ids]
    return [
        " ".join([tag] + [str(c[k]) for c in id_columns] + fields)
        for k, fields in enumerate(number_fields(numbers))
    ]


def _pose_numbers(values, g2o_quaternion: bool) -> np.ndarray:
    if isinstance(values, SE2):
        return values.as_xytheta()
    q, t = values.as_quaternion_translation()
    if g2o_quaternion:
        return np.concatenate([t, q], axis=1)
    return np.concatenate([t, matrix_to_rpy(values.rotation)], axis=1)


def _sim3_numbers(element: Sim3, dialect: str) -> np.ndarray:
    """Dialect (a): the element (q, t, s); dialect (b): its log, in g2o's tangent order."""
    if dialect == "a":
        return np.concatenate(
            [element.as_quaternion(), element.translation, element.scale[:, None]], 1
        )
    return sim3_to_g2o_tangent(element)


def sim3_edge_lines(
    i_ids: np.ndarray,
    j_ids: np.ndarray,
    measurements: Sim3,
    information: np.ndarray,
    dialect: str = "a",
) -> list[str]:
    """EDGE_SIM3:EXPMAP lines for edges i → j with our measurements (g2o's Z is their inverse,
    which dialect (b) writes as its log, so that is our element's log)."""
    if dialect not in ("a", "b"):
        raise ValueError(f"Sim3 dialect is 'a' or 'b', not {dialect!r}")
    measured = measurements.inverse() if dialect == "a" else measurements
    numbers = np.hstack([_sim3_numbers(measured, dialect), sim3_information_to_file(information)])
    return _lines("EDGE_SIM3:EXPMAP", [i_ids, j_ids], numbers)


MEASUREMENT_TAGS = {
    "g2o": {SE2: ("EDGE_SE2", "EDGE_PRIOR_SE2"), SE3: ("EDGE_SE3:QUAT", "EDGE_SE3_PRIOR")},
    "toro": {SE2: ("EDGE2", None), SE3: ("EDGE3", None)},
}
"""The tags a graph's between edges and priors are written with, by format and group."""
MEASUREMENT_TAGS["g2o"][Sim3] = ("EDGE_SIM3:EXPMAP", None)

Rejected = tuple[np.ndarray, np.ndarray]
"""Masks over a graph's between edges and over its priors of those a robust run rejected."""


def _marked(lines: list[str], rejected: Rejected | None, tags: tuple) -> list[str]:
    """The lines, those of the rejected edges and priors (in order of their tags ``tags``)
    behind ``REJECTED_PREFIX``."""
    if rejected is None:
        return lines
    masks = {tag: mask for tag, mask in zip(tags, rejected, strict=True) if tag is not None}
    seen = dict.fromkeys(masks, 0)
    marked = []
    for line in lines:
        tag = line.split(" ", 1)[0]
        if tag in masks:
            if masks[tag][seen[tag]]:
                line = REJECTED_PREFIX + line
            seen[tag] += 1
        marked.append(line)
    return marked


@paused_garbage_collection()
def format_g2o(
    graph: PoseGraph,
    g2o_rotation_information: bool = False,
    sim3_dialect: str = "a",
    rejected: Rejected | None = None,
) -> str:
    """The graph as g2o text (VERTEX/EDGE lines of its group, priors, then FIX lines); the
    ``rejected`` edges and priors marked as such (``_marked``)."""
    _refuse_unwritable(graph, "g2o")
    ids, edges, priors = graph.node_ids, graph.edges, graph.priors
    i, j = ids[edges.i], ids[edges.j]
    lines: list[str] = []
    if graph.group is SE2:
        lines += _lines("VERTEX_SE2", [ids], graph.values.as_xytheta())
        info = upper_from_symmetric(edges.information)
        lines += _lines("EDGE_SE2", [i, j], np.hstack([edges.measurements.as_xytheta(), info]))
        prior_info = upper_from_symmetric(priors.information)
        prior_numbers = np.hstack([priors.measurements.as_xytheta(), prior_info])
        lines += _lines("EDGE_PRIOR_SE2", [ids[priors.i]], prior_numbers)
    elif graph.group is SE3:
        if len(priors):  # g2o's EDGE_SE3_PRIOR names an offset parameter, defined first
            lines += _lines(
                "PARAMS_SE3OFFSET", [np.zeros(1, int)], _pose_numbers(SE3.identity((1,)), True)
            )
        lines += _lines("VERTEX_SE3:QUAT", [ids], _pose_numbers(graph.values, True))
        info = se3_information_to_file(edges.information, g2o_rotation_information)
        lines += _lines(
            "EDGE_SE3:QUAT", [i, j], np.hstack([_pose_numbers(edges.measurements, True), info])
        )
        prior_info = se3_information_to_file(priors.information, g2o_rotation_information)
        prior_numbers = np.hstack([_pose_numbers(priors.measurements, True), prior_info])
        lines += _lines(
            "EDGE_SE3_PRIOR", [ids[priors.i], np.zeros(len(priors), int)], prior_numbers
        )
    else:
        if sim3_dialect not in ("a", "b"):
            raise ValueError(f"Sim3 dialect is 'a' or 'b', not {sim3_dialect!r}")
        # g2o stores the world → camera element Sᵢ = Xᵢ⁻¹ and the edge Z = (our measurement)⁻¹,
        # except dialect (b), which writes log(Sᵢ⁻¹) and log(Z⁻¹): our elements themselves.
        vertices = graph.values.inverse() if sim3_dialect == "a" else graph.values
        measured = edges.measurements.inverse() if sim3_dialect == "a" else edges.measurements
        vertex_numbers = _sim3_numbers(vertices, sim3_dialect)
        if sim3_dialect == "b":  # followed by fx fy cx cy, which the graph does not hold
            vertex_numbers = np.hstack(
                [vertex_numbers, np.tile([1.0, 1.0, 0.0, 0.0], (len(ids), 1))]
            )
        lines += _lines("VERTEX_SIM3:EXPMAP", [ids], vertex_numbers)
        info = sim3_information_to_file(edges.information)
        lines += _lines(
            "EDGE_SIM3:EXPMAP", [i, j], np.hstack([_sim3_numbers(measured, sim3_dialect), info])
        )
    lines += [f"FIX {k}" for k in ids[graph.fixed].tolist()]
    lines = _marked(lines, rejected, MEASUREMENT_TAGS["g2o"][graph.group])
    return "\n".join(lines) + "\n"


def unwritable(
    graph: PoseGraph, file_format: str, group: type[LieGroup] | None = None
) -> str | None:
    """Why ``file_format`` ("g2o" or "toro") cannot hold ``graph``, or the graph lifted to
    ``group``; None if it can. Both hold node ids 0 to 2⁶³ − 1 (as the reader takes them),
    while a graph's ids may be negative. TORO has no Sim3, prior or FIX lines; g2o has no Sim3
    prior."""
    group = graph.group if group is None else group
    negative = graph.node_ids[graph.node_ids < 0]
    if negative.size:
        name = "g2o" if file_format == "g2o" else "TORO"
        return f"{name} files hold node ids 0 to 2⁶³ − 1, not {negative[0]}"
    if file_format == "toro" and group is Sim3:
        return "TORO has no Sim3 lines; write g2o instead"
    if file_format == "toro" and (len(graph.priors) or graph.fixed.any()):
        return "TORO has no prior or FIX lines; write g2o to keep them"
    if file_format == "g2o" and group is Sim3 and len(graph.priors):
        return (
            "g2o has no Sim3 prior line; write the poses as TUM or KITTI, or the graph without"
            " its priors"
        )
    return None


def _refuse_unwritable(graph: PoseGraph, file_format: str) -> None:
    reason = unwritable(graph, file_format)
    if reason is not None:
        raise ValueError(reason)


@paused_garbage_collection()
def format_toro(graph: PoseGraph, rejected: Rejected | None = None) -> str:
    """The graph as TORO text (VERTEX2/EDGE2 or VERTEX3/EDGE3, then EQUIV lines); the
    ``rejected`` edges marked as such (``_marked``)."""
    _refuse_unwritable(graph, "toro")
    ids, edges = graph.node_ids, graph.edges
    i, j = ids[edges.i], ids[edges.j]
    if graph.group is SE2:
        lines = _lines("VERTEX2", [ids], graph.values.as_xytheta())
        info = toro2_information_to_file(edges.information)
        lines += _lines("EDGE2", [i, j], np.hstack([edges.measurements.as_xytheta(), info]))
    else:
        lines = _lines("VERTEX3", [ids], _pose_numbers(graph.values, False))
        info = upper_from_symmetric(edges.information)
        lines += _lines(
            "EDGE3", [i, j], np.hstack([_pose_numbers(edges.measurements, False), info])
        )
    lines += [f"EQUIV {a} {b}" for a, b in graph.equivalences.tolist()]
    lines = _marked(lines, rejected, MEASUREMENT_TAGS["toro"][graph.group])
    return "\n".join(lines) + "\n"


def write_graph(
    graph: PoseGraph,
    path: str,
    file_format: str | None = None,
    g2o_rotation_information: bool = False,
    sim3_dialect: str = "a",
    rejected: Rejected | None = None,
) -> None:
    """Write atomically; the format is "g2o" or "toro", or told by the suffix (.g2o; .graph or
    .toro). A path whose suffix tells neither is refused unless the format is given. The
    ``rejected`` edges and priors (masks) are written commented out behind
    ``REJECTED_PREFIX``: g2o and gtsam leave them out, posegraph reads them back as rejected."""
    refuse_non_finite(path, graph.node_ids, graph.values)
    if file_format is None:
        file_format = GRAPH_SUFFIXES.get(Path(path).suffix.lower())
        if file_format is None:
            raise ValueError(
                f"{path}: its suffix tells no graph format (.g2o, or .graph or .toro for TORO);"
                " give file_format 'g2o' or 'toro'"
            )
    if file_format not in ("g2o", "toro"):
        raise ValueError(f"unknown graph format {file_format!r}; use 'g2o' or 'toro'")
    with written_finite(path):
        if file_format == "toro":
            text = format_toro(graph, rejected)
        else:
            text = format_g2o(graph, g2o_rotation_information, sim3_dialect, rejected)
    atomic_write_text(path, text)
