"""The graph of a file's records: nodes in vertex order, edges and priors to known nodes (the
others reported), holds and TORO's equivalences. Nodes without a vertex line have no value
(``PoseGraph.initialized``): the file gives none."""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from ..graph import PoseGraph
from ..lie import SE3
from ..problem.factors import between_squares, prior_squares
from .parsing import LineChecker, Rows
from .records import ALL_TAGS, Collected

_ASCII_BLANKS = re.compile(r"[ \t\r\v\f]+")


@dataclasses.dataclass(frozen=True)
class SE3Lines:
    """Which edges and priors of a Sim3 graph were read from SE3 lines (a file mixing SE3
    odometry and Sim3 loops): masks over ``graph.edges`` and ``graph.priors``. Such lines are
    read at scale 1 with no information on log-scale (``records.embed_se3_records``)."""

    edges: np.ndarray
    priors: np.ndarray


def skipped_vertex_lines(lines_by_tag: dict[str, list], checker: LineChecker) -> dict[int, int]:
    """Node id → number of its first vertex line that lenient reading skipped (ids that are
    not ASCII integers from 0 to 2⁶³ − 1 left out)."""
    if not checker.skipped:
        return {}
    skipped = {line for line, _ in checker.skipped}
    found: dict[int, int] = {}
    for tag, entries in lines_by_tag.items():
        if ALL_TAGS[tag].kind != "vertex":
            continue
        for number, text in entries:
            if number in skipped:
                token = _ASCII_BLANKS.split(text.strip(" \t\r\v\f"), maxsplit=1)[0]
                if not (token.isascii() and token.isdigit()):  # int() reads "1_0" and "٣"
                    continue
                node = int(token)
                if node < 2**63:
                    found.setdefault(node, number)
    return found


@dataclasses.dataclass
class _Measured:
    """Edges or priors to add, per record (node ids…, measurements, information), and per
    measurement its line, its tag and whether it was an SE3 line."""

    parts: list = dataclasses.field(default_factory=list)
    lines: list = dataclasses.field(default_factory=lambda: [np.zeros(0, np.int64)])
    tags: list = dataclasses.field(default_factory=list)
    from_se3: list = dataclasses.field(default_factory=lambda: [np.zeros(0, bool)])


def _known(records: list, columns, known_ids, check: bool, checker, skipped_vertices) -> _Measured:
    """The records' measurements whose nodes are known (``_filter_known``)."""
    measured = _Measured()
    for rows, measurements, information in records:
        kept = _filter_known(rows, columns, known_ids, check, checker, skipped_vertices)
        ids = [rows.ids(column)[kept] for column in columns]
        measured.parts.append((*ids, measurements[kept], information[kept]))
        measured.lines.append(rows.line_numbers[kept])
        measured.tags += [rows.tag] * int(np.count_nonzero(kept))
        measured.from_se3.append(np.full(np.count_nonzero(kept), ALL_TAGS[rows.tag].group is SE3))
    return measured


def _finite_errors(graph: PoseGraph, edges: _Measured, priors: _Measured, checker) -> tuple:
    """Masks of the edges and of the priors whose error at the file's values is finite, or
    whose nodes have no value; the others are reported on their lines (values so far apart
    that their error overflows, as a vertex at 1e200 makes it)."""
    has_value = graph.initialized
    with np.errstate(all="ignore"):
        edge_errors = between_squares(graph.values, graph.edges)
        prior_errors = prior_squares(graph.values, graph.priors)
    edges_kept = np.isfinite(edge_errors) | ~(has_value[graph.edges.i] & has_value[graph.edges.j])
    priors_kept = np.isfinite(prior_errors) | ~has_value[graph.priors.i]
    for kept, measured in ((edges_kept, edges), (priors_kept, priors)):
        lines = np.concatenate(measured.lines)
        for k in np.flatnonzero(~kept):
            checker.fail(
                int(lines[k]),
                f"{measured.tags[k]}: its error at the file's values overflows: a number is out"
                " of range (a value too large for double precision)",
            )
    return edges_kept, priors_kept


def assemble(
    group, collected: Collected, checker: LineChecker, skipped_vertices: dict, rejected: set
):
    """The graph of the lines collected, the ids of its nodes without a vertex value, the
    masks of its edges and of its priors read from SE3 lines (``SE3Lines``), and the masks of
    those on the ``rejected`` lines (None if none).

    Edges and priors may name nodes without a vertex line only in a file that has none; then
    no node has a value. A node whose vertex line lenient reading skipped
    (``skipped_vertices``) keeps its edges and has no value. Edges and priors whose error at
    the file's values overflows are reported (``_finite_errors``).
    """
    vertex_ids, vertex_lines, values = _vertices(group, collected, checker)
    salvaged = np.setdiff1d(np.fromiter(skipped_vertices, np.int64), vertex_ids)
    known_ids = np.concatenate([vertex_ids, salvaged])
    check = bool(collected.vertices)
    edges = _known(collected.edges, (0, 1), known_ids, check, checker, skipped_vertices)
    priors = _known(collected.priors, (0,), known_ids, check, checker, skipped_vertices)

    endpoints = [part[k] for part in edges.parts for k in (0, 1)] + [p[0] for p in priors.parts]
    without_vertex = np.unique(np.concatenate(endpoints)) if endpoints else np.zeros(0, np.int64)
    if check:
        without_vertex = without_vertex[np.isin(without_vertex, salvaged)]
    # Nodes in vertex order, a skipped vertex line's node in its line's place; by id without.
    order = np.arange(without_vertex.size)
    if check:
        skipped_lines = [skipped_vertices[node] for node in without_vertex.tolist()]
        order = np.argsort(np.concatenate([vertex_lines, skipped_lines]), kind="stable")
    node_ids = np.concatenate([vertex_ids, without_vertex])[order]
    graph = PoseGraph(group)
    graph.add_nodes(
        node_ids, group.concatenate([values, group.identity(without_vertex.shape)])[order]
    )
    for part in edges.parts:
        graph.add_edges(*part)
    for part in priors.parts:
        graph.add_priors(*part)
    graph.initialized = ~np.isin(graph.node_ids, without_vertex)  # ``load_graph`` composes
    edges_kept, priors_kept = _finite_errors(graph, edges, priors, checker)
    graph.remove_edges(~edges_kept)
    graph.remove_priors(~priors_kept)
    _add_holds(graph, collected, checker, skipped_vertices)
    se3_edges = np.concatenate(edges.from_se3)[edges_kept]
    se3_priors = np.concatenate(priors.from_se3)[priors_kept]
    se3_lines = None
    if group is not SE3 and (se3_edges.any() or se3_priors.any()):
        se3_lines = SE3Lines(se3_edges, se3_priors)
    marked = None
    if rejected:
        marked = tuple(
            np.isin(np.concatenate(measured.lines)[kept], list(rejected))
            for measured, kept in ((edges, edges_kept), (priors, priors_kept))
        )
    return graph, without_vertex, se3_lines, marked


def _add_holds(graph: PoseGraph, collected: Collected, checker, skipped_vertices: dict) -> None:
    """The FIX lines' holds and TORO's equivalences, on known nodes."""
    for rows in collected.fixes:
        kept = _filter_known(rows, (0,), graph.node_ids, True, checker, skipped_vertices)
        graph.fix(rows.ids(0)[kept])
    for rows in collected.equivalences:
        kept = _filter_known(rows, (0, 1), graph.node_ids, True, checker, skipped_vertices)
        pairs = np.stack([rows.ids(0)[kept], rows.ids(1)[kept]], axis=1)
        graph.equivalences = np.concatenate([graph.equivalences, pairs])


def _vertices(group, collected: Collected, checker: LineChecker):
    """(ids, line numbers, values) of the vertex lines in line order; a vertex defined again
    is reported and its later lines left out."""
    if not collected.vertices:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, group.identity((0,))
    rows = [r for r, _ in collected.vertices]
    vertex_ids = np.concatenate([r.ids(0) for r in rows])
    lines = np.concatenate([r.line_numbers for r in rows])
    values = group.concatenate([v for _, v in collected.vertices])
    order = np.argsort(lines, kind="stable")
    vertex_ids, lines, values = vertex_ids[order], lines[order], values[order]
    _, first = np.unique(vertex_ids, return_index=True)
    duplicate = np.ones(vertex_ids.size, dtype=bool)
    duplicate[first] = False
    for k in np.flatnonzero(duplicate):
        original = lines[np.flatnonzero(vertex_ids == vertex_ids[k])[0]]
        checker.fail(
            int(lines[k]), f"vertex {vertex_ids[k]} is defined again (first on line {original})"
        )
    kept = ~duplicate
    return vertex_ids[kept], lines[kept], values[kept]


def _filter_known(
    rows: Rows, columns, known_ids: np.ndarray, check: bool, checker, skipped_vertices: dict
) -> np.ndarray:
    """Mask of rows whose ids in ``columns`` are known nodes; the others are reported."""
    keep = np.ones(len(rows), dtype=bool)
    if not check:
        return keep
    for column in columns:
        ids = rows.ids(column)
        unknown = keep & ~np.isin(ids, known_ids)
        for k in np.flatnonzero(unknown):
            node = int(ids[k])
            why = (
                f"whose vertex line (line {skipped_vertices[node]}) was skipped"
                if node in skipped_vertices
                else "which has no vertex line"
            )
            checker.fail(int(rows.line_numbers[k]), f"{rows.tag}: refers to node {node}, {why}")
        keep &= ~unknown
    return keep
