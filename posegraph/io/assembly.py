"""The graph of a file's records: nodes in vertex order, edges and priors to known nodes (the
others reported), holds and TORO's equivalences. Nodes without a vertex line have no value
(``PoseGraph.initialized``): the file gives none."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph
from ..lie import SE3
from .parsing import LineChecker, Rows
from .records import ALL_TAGS, Collected


@dataclasses.dataclass(frozen=True)
class SE3Lines:
    """Which edges and priors of a Sim3 graph were read from SE3 lines (a file mixing SE3
    odometry and Sim3 loops): masks over ``graph.edges`` and ``graph.priors``. Such lines are
    read at scale 1 with no information on log-scale (``records.embed_se3_records``)."""

    edges: np.ndarray
    priors: np.ndarray


def skipped_vertex_lines(lines_by_tag: dict[str, list], checker: LineChecker) -> dict[int, int]:
    """Node id → number of its first vertex line that lenient reading skipped (ids that are
    not integers from 0 to 2⁶³ − 1 left out)."""
    if not checker.skipped:
        return {}
    skipped = {line for line, _ in checker.skipped}
    found: dict[int, int] = {}
    for tag, entries in lines_by_tag.items():
        if ALL_TAGS[tag].kind != "vertex":
            continue
        for number, text in entries:
            if number in skipped:
                try:
                    node = int(text.split(None, 1)[0])
                except (ValueError, IndexError):
                    continue
                if 0 <= node < 2**63:
                    found.setdefault(node, number)
    return found


def assemble(group, collected: Collected, checker: LineChecker, skipped_vertices: dict):
    """The graph of the lines collected, the ids of its nodes without a vertex value, and the
    masks of its edges and of its priors read from SE3 lines (``SE3Lines``).

    Edges and priors may name nodes without a vertex line only in a file that has none; then
    no node has a value. A node whose vertex line lenient reading skipped
    (``skipped_vertices``) keeps its edges and has no value.
    """
    vertex_ids, vertex_lines, values = _vertices(group, collected, checker)
    salvaged = np.setdiff1d(np.fromiter(skipped_vertices, np.int64), vertex_ids)
    known_ids = np.concatenate([vertex_ids, salvaged])
    check = bool(collected.vertices)
    edges, edges_from_se3 = [], []
    for rows, measurements, information in collected.edges:
        kept = _filter_known(rows, (0, 1), known_ids, check, checker, skipped_vertices)
        edges.append((rows.ids(0)[kept], rows.ids(1)[kept], measurements[kept], information[kept]))
        edges_from_se3.append(np.full(np.count_nonzero(kept), ALL_TAGS[rows.tag].group is SE3))
    priors, priors_from_se3 = [], []
    for rows, measurements, information in collected.priors:
        kept = _filter_known(rows, (0,), known_ids, check, checker, skipped_vertices)
        priors.append((rows.ids(0)[kept], measurements[kept], information[kept]))
        priors_from_se3.append(np.full(np.count_nonzero(kept), ALL_TAGS[rows.tag].group is SE3))

    endpoints = [e[0] for e in edges] + [e[1] for e in edges] + [p[0] for p in priors]
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
    for i, j, measurements, information in edges:
        graph.add_edges(i, j, measurements, information)
    for i, measurements, information in priors:
        graph.add_priors(i, measurements, information)
    for rows in collected.fixes:
        kept = _filter_known(rows, (0,), graph.node_ids, True, checker, skipped_vertices)
        graph.fix(rows.ids(0)[kept])
    for rows in collected.equivalences:
        kept = _filter_known(rows, (0, 1), graph.node_ids, True, checker, skipped_vertices)
        pairs = np.stack([rows.ids(0)[kept], rows.ids(1)[kept]], axis=1)
        graph.equivalences = np.concatenate([graph.equivalences, pairs])
    if without_vertex.size:  # no value read: ``load.load_graph`` composes them
        graph.initialized = ~np.isin(graph.node_ids, without_vertex)
    se3_lines = None
    if group is not SE3 and any(mask.any() for mask in edges_from_se3 + priors_from_se3):
        se3_lines = SE3Lines(
            np.concatenate(edges_from_se3 + [np.zeros(0, bool)]),
            np.concatenate(priors_from_se3 + [np.zeros(0, bool)]),
        )
    return graph, without_vertex, se3_lines


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
