"""Read g2o and TORO pose-graph files into a ``PoseGraph``, strictly or leniently."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np

from ..graph import PoseGraph, element_problems, information_problems, overflowing_edges
from ..initialization import align_to_priors, spanning_tree_values
from ..lie import SE3, Sim3
from ..lifting import (
    check_scale_information,
    default_scale_information,
    lift_information,
    lift_se3,
    loop_scale_sigma,
)
from .errors import GraphFileError
from .parsing import (
    LineChecker,
    Rows,
    paused_garbage_collection,
    quaternion_problems,
    read_tagged_lines,
    to_rows,
)
from .tags import (
    EDGE2_ORDERS,
    G2O_TAGS,
    LANDMARK_TAGS,
    TORO_TAGS,
    TagFormat,
    edge2_information,
    edge2_order_text,
    prior_without_offset,
)

ALL_TAGS: dict[str, TagFormat] = {**G2O_TAGS, **TORO_TAGS}
_NO_ENDS = np.zeros((0, 2), np.int64)


@dataclasses.dataclass(frozen=True)
class ReadOptions:
    """How to read a file.

    Attributes:
        lenient: skip bad lines and unknown tags (reported in ``ReadResult.skipped``) instead of
            stopping at the first.
        g2o_rotation_information: read SE3 information the way g2o itself weighs it
            (Λ_φφ = Λ_qq/4, Λ_ρφ = Λ_ρq/2) instead of as-is over (ρ, φ) like gtsam.
        identity_information: weigh every edge and prior by the identity, ignoring the file's
            information (TORO's -ic, for files whose information is missing or not trusted);
            lines may then omit their information values.
        edge2_order: the order of the six information values of TORO's EDGE2 lines: "toro"
            (I11 I12 I22 I33 I13 I23, TORO's own) or "g2o" (the upper triangle, row-major, as
            gtsam's ``readG2o`` reads them).
        scale_information: see below.
    """

    lenient: bool = False
    g2o_rotation_information: bool = False
    identity_information: bool = False
    edge2_order: str = "toro"
    scale_information: float | None = None
    """For files mixing SE3 and Sim3 lines (monocular odometry plus Sim3 loop closures): the SE3
    lines are lifted to Sim3 with scale 1 and this information on log-scale (None:
    ``posegraph.lifting.default_scale_information`` of the SE3 edges and of the scale change per
    edge that the Sim3 edges call for, ``posegraph.lifting.loop_scale_sigma``)."""

    def __post_init__(self) -> None:
        if self.edge2_order not in EDGE2_ORDERS:
            raise ValueError(
                f"edge2_order must be one of {', '.join(EDGE2_ORDERS)}, not {self.edge2_order!r}"
            )
        check_scale_information(self.scale_information)


@dataclasses.dataclass(frozen=True)
class ReadResult:
    """A graph and what reading it found."""

    graph: PoseGraph
    path: str
    format: str
    """"g2o" or "toro"."""
    tag_counts: dict[str, int]
    """Lines read per tag (skipped lines excluded)."""
    skipped: list[tuple[int, str]]
    """(line, reason) of every line skipped in lenient mode, in line order."""
    nodes_without_vertex: np.ndarray
    """Ids of nodes that had no vertex line (or only ones that lenient reading skipped), their
    values composed along a spanning tree from the nodes that have values."""
    sim3_dialect: str | None
    """"a" (element) or "b" (log of the inverse) for Sim3 files."""
    lifted_scale_information: float | None = None
    """In a file mixing SE3 and Sim3 lines, the information on log-scale that the SE3 edges and
    priors were lifted to Sim3 with (``ReadOptions.scale_information``, or its default); None
    if none were lifted."""

    def skipped_by_reason(self) -> list[tuple[str, int, int]]:
        """(reason, how many lines, the first one's number) of the skipped lines, most frequent
        reason first (ties in the order of their first line)."""
        return skipped_by_reason(self.skipped)

    def skipped_report(self, reasons: int = 3) -> str:
        """The report "N line(s) skipped: k × reason (first at line L); …" of the skipped lines,
        naming the ``reasons`` most frequent reasons."""
        return skipped_report(self.skipped, reasons)


def skipped_by_reason(skipped: list[tuple[int, str]]) -> list[tuple[str, int, int]]:
    """``ReadResult.skipped_by_reason`` of (line, reason) pairs in line order."""
    first_line: dict[str, int] = {}
    for line, why in skipped:
        first_line.setdefault(why, line)
    counts = Counter(why for _, why in skipped)
    return [(why, count, first_line[why]) for why, count in counts.most_common()]


def skipped_report(skipped: list[tuple[int, str]], reasons: int = 3) -> str:
    """``ReadResult.skipped_report`` of (line, reason) pairs in line order."""
    grouped = skipped_by_reason(skipped)
    named = "; ".join(
        f"{count} × {why} (first at line {line})" for why, count, line in grouped[:reasons]
    )
    more = "; …" if len(grouped) > reasons else ""
    return f"{len(skipped)} line(s) skipped: {named}{more}"


@dataclasses.dataclass
class _Collected:
    """Converted rows per kind, before the graph is assembled."""

    vertices: list = dataclasses.field(default_factory=list)  # (rows, values)
    edges: list = dataclasses.field(default_factory=list)  # (rows, measurements, information)
    priors: list = dataclasses.field(default_factory=list)
    parameters: list = dataclasses.field(default_factory=list)  # (rows, SE3 offsets)
    fixes: list = dataclasses.field(default_factory=list)  # rows
    equivalences: list = dataclasses.field(default_factory=list)  # rows


def _lift_se3_records(collected: _Collected, scale_information: float | None) -> float | None:
    """Turn SE3 vertices, edges and priors into Sim3 ones of scale 1 (CONVENTIONS.md: both
    files' vertices are world-from-node, so no inversion is involved); returns the log-scale
    information of the lifted edges and priors, None if there were none."""
    se3_edges = [(rows, z, info) for rows, z, info in collected.edges if isinstance(z, SE3)]
    lifted = bool(se3_edges) or any(isinstance(z, SE3) for _, z, _ in collected.priors)
    if scale_information is None:
        loops = [(rows, z) for rows, z, _ in collected.edges if isinstance(z, Sim3)]
        sigma = loop_scale_sigma(
            np.concatenate([rows.node_ids[:, :2] for rows, _, _ in se3_edges] + [_NO_ENDS]),
            np.concatenate([rows.node_ids[:, :2] for rows, _ in loops] + [_NO_ENDS]),
            np.concatenate([z.scale for _, z in loops] + [np.zeros(0)]),
        )
        scale_information = default_scale_information(
            np.concatenate([info for *_, info in se3_edges] + [np.zeros((0, 6, 6))]),
            SE3.concatenate([z for _, z, _ in se3_edges] + [SE3.identity((0,))]),
            sigma,
        )
    collected.vertices = [
        (rows, lift_se3(values) if isinstance(values, SE3) else values)
        for rows, values in collected.vertices
    ]
    for kind in ("edges", "priors"):
        setattr(
            collected,
            kind,
            [
                (rows, lift_se3(z), lift_information(info, scale_information))
                if isinstance(z, SE3)
                else (rows, z, info)
                for rows, z, info in getattr(collected, kind)
            ],
        )
    return scale_information if lifted else None


def _edge2_order_advice(rows: Rows, order: str) -> str:
    """Advice for EDGE2 lines whose information is refused in ``order``: whether every one of
    them is accepted in the other order (files of both kinds exist)."""
    other = next(name for name in EDGE2_ORDERS if name != order)
    if information_problems(edge2_information(rows.numbers[:, 5:11], other))[0].any():
        return ""
    return (
        f" in the {order} order ({edge2_order_text(order)}); every EDGE2 line of this file is"
        f" positive semi-definite in the {other} order ({edge2_order_text(other)}): read it with"
        f" --edge2-order {other} (ReadOptions(edge2_order={other!r}))"
    )


def _drop(rows: Rows, measurements, information, bad: np.ndarray, message, checker: LineChecker):
    """The rows, measurements and information where ``bad`` does not hold; the rows where it
    does go to ``checker`` with ``message(k)``."""
    if not bad.any():
        return rows, measurements, information
    return checker.keep_good(rows, bad, message), measurements[~bad], information[~bad]


def _check_information(rows: Rows, measurements, information, checker: LineChecker, options):
    bad, why = information_problems(information)
    advice = ""
    if rows.tag == "EDGE2" and bad.any():
        advice = _edge2_order_advice(rows, options.edge2_order)
    return _drop(
        rows,
        measurements,
        information,
        bad,
        lambda k: f"information matrix is {why(k)}{advice}",
        checker,
    )


def _check_overflow(rows: Rows, measurements, information, checker: LineChecker):
    """The edges whose information at their start node is finite (``overflowing_edges``)."""
    return _drop(
        rows,
        measurements,
        information,
        overflowing_edges(measurements, information),
        lambda k: (
            "a number is out of range: the edge's translation weighed by its information "
            f"overflows (Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) at node {rows.ids(0)[k]})"
        ),
        checker,
    )


def _pad_missing_information(entries: list, spec: TagFormat) -> list:
    """Lines that omit their information get zeros in its place (for identity_information, which
    replaces every information after parsing)."""
    short, missing = spec.widths_without_information, spec.information_values
    return [
        (number, text + " 0" * missing if len(text.split()) in short else text)
        for number, text in entries
    ]


def _finite(rows: Rows, pieces: tuple, checker: LineChecker) -> tuple[Rows, tuple]:
    """The rows whose pieces (a group element, then information matrices) are finite, and the
    element's inverse too, and whose element the graph accepts (``element_problems``), and
    their pieces; the others are refused: a number overflowed, or underflowed (a Sim3
    log-scale of ±1e20 gives a scale of ∞ or 0, a scale of 1e120 an inverse of determinant
    1e-360, which is 0)."""
    matrices = pieces[0].as_matrix()
    finite = np.isfinite(matrices).all(axis=(1, 2))
    finite &= np.isfinite(pieces[0].inverse().as_matrix()).all(axis=(1, 2))
    for information in pieces[1:]:
        finite &= np.isfinite(information).all(axis=(1, 2))
    degenerate, why = element_problems(matrices)
    keep = finite & ~degenerate
    if keep.all():
        return rows, pieces
    rows = checker.keep_good(
        rows,
        ~keep,
        lambda k: (
            "a number is out of range: the line's pose or information overflows"
            if not finite[k]
            else f"the line's pose is not an element of {type(pieces[0]).__name__} (its "
            f"matrix has {why(k)})"
        ),
    )
    return rows, tuple(piece[keep] for piece in pieces)


def _parse(spec: TagFormat, rows: Rows, options: ReadOptions, checker: LineChecker):
    """(rows, ``spec.parse`` of them), without the rows whose numbers overflow."""
    with np.errstate(all="ignore"):  # overflow is found by _finite
        parsed = spec.parse(rows.numbers, options)
        if isinstance(parsed, tuple):
            return _finite(rows, parsed, checker)
        rows, (values,) = _finite(rows, (parsed,), checker)
    return rows, values


def _convert(spec: TagFormat, rows: Rows, options: ReadOptions, checker, collected):
    columns = spec.quaternion.get(rows.numbers.shape[1])
    if columns is not None:
        problems = quaternion_problems(rows.numbers[:, columns])
        bad = np.zeros(len(rows), dtype=bool)
        bad[list(problems)] = True
        rows = checker.keep_good(rows, bad, problems.__getitem__)
    if not len(rows):
        return
    if spec.kind == "vertex":
        collected.vertices.append(_parse(spec, rows, options, checker))
    elif spec.kind in ("edge", "prior"):
        if spec.kind == "edge":
            loops = rows.ids(0) == rows.ids(1)
            rows = checker.keep_good(
                rows, loops, lambda k: f"edge from node {rows.ids(0)[k]} to itself"
            )
            if not len(rows):
                return
        rows, (measurements, information) = _parse(spec, rows, options, checker)
        if options.identity_information:
            information = np.broadcast_to(np.eye(spec.group.dof), information.shape).copy()
        converted = _check_information(rows, measurements, information, checker, options)
        if spec.kind == "edge":
            converted = _check_overflow(*converted, checker)
        if len(converted[0]):
            (collected.edges if spec.kind == "edge" else collected.priors).append(converted)
    elif spec.kind == "parameter":
        collected.parameters.append(_parse(spec, rows, options, checker))
    elif spec.kind == "fix":
        collected.fixes.append(rows)
    else:
        collected.equivalences.append(rows)


def _offsets(collected: _Collected, checker: LineChecker) -> tuple[dict[float, int], SE3]:
    """The PARAMS_SE3OFFSET lines: each parameter id's position, and the offsets."""
    position: dict[float, int] = {}
    first_line: dict[float, int] = {}
    kept = []
    for rows, offsets in collected.parameters:
        lines, keys = rows.line_numbers.tolist(), rows.numbers[:, 0].tolist()
        for k, (line, key) in enumerate(zip(lines, keys, strict=True)):
            if key in position:
                checker.fail(
                    line,
                    f"PARAMS_SE3OFFSET {key:g} is defined again (first on line {first_line[key]})",
                )
                continue
            position[key], first_line[key] = len(kept), line
            kept.append(offsets[k : k + 1])
    return position, SE3.concatenate(kept) if kept else SE3.identity((0,))


def _prior_on_node(record: tuple, position: dict[float, int], offsets: SE3, checker) -> tuple:
    """An EDGE_SE3_PRIOR record (rows, measurements, information) re-expressed on its node itself
    (``prior_without_offset``), with the offset its line names."""
    rows, measurements, information = record
    keys = rows.numbers[:, 1]
    undefined = ~np.isin(keys, list(position))
    rows = checker.keep_good(
        rows,
        undefined,
        lambda k: (
            f"offset parameter {keys[k]:g} is not defined by a PARAMS_SE3OFFSET line (for no"
            f" offset, add 'PARAMS_SE3OFFSET {keys[k]:g} 0 0 0 0 0 0 1' before it, as g2o does)"
        ),
    )
    used = offsets[np.array([position[key] for key in keys[~undefined].tolist()], dtype=int)]
    with np.errstate(all="ignore"):  # overflow is found by _finite
        moved = prior_without_offset(measurements[~undefined], information[~undefined], used)
        rows, (measurements, information) = _finite(rows, moved, checker)
    return rows, measurements, information


def _apply_prior_offsets(collected: _Collected, checker: LineChecker) -> None:
    """Re-express every EDGE_SE3_PRIOR on its node (g2o priors measure the node's offset pose)."""
    position, offsets = _offsets(collected, checker)
    collected.priors = [
        _prior_on_node(record, position, offsets, checker)
        if record[0].tag == "EDGE_SE3_PRIOR"
        else record
        for record in collected.priors
    ]


@paused_garbage_collection()
def read_graph(path: str, options: ReadOptions | None = None) -> ReadResult:
    """Read a g2o or TORO file (told apart by their tags).

    Raises ``GraphFileError`` naming ``file:line`` and the problem. The checks run in three
    stages: the tags, each line's numbers, then what lines refer to (a vertex defined again,
    an edge to a node without a vertex line). Strict reading stops at the first stage that
    finds bad lines and names the earliest of them, with how many it found. Nodes that appear
    only in edges are created; when the file has no vertex lines at all, every node is
    initialised by composing odometry along a spanning tree.
    """
    path = str(path)
    options = ReadOptions() if options is None else options
    checker = LineChecker(path, options.lenient)
    lines_by_tag: dict[str, list] = {}
    for number, tag, text in read_tagged_lines(path):
        if tag not in ALL_TAGS:
            checker.fail(number, _unknown_tag_reason(tag, options))
            continue
        lines_by_tag.setdefault(tag, []).append((number, text))
    checker.raise_first()
    if not lines_by_tag:
        found = skipped_report(sorted(checker.skipped)) if checker.skipped else "is the file empty?"
        raise GraphFileError(path, None, f"holds no vertices or edges ({found})")

    first_line_of_group: dict = {}
    for tag, entries in lines_by_tag.items():
        group = ALL_TAGS[tag].group
        if group is not None:
            first_line_of_group[group] = min(
                first_line_of_group.get(group, entries[0][0]), entries[0][0]
            )
    groups = set(first_line_of_group)
    if groups == {SE3, Sim3}:  # SE3 odometry with Sim3 loop closures: one Sim3 graph
        groups = {Sim3}
    if len(groups) > 1:
        in_order = sorted(groups, key=first_line_of_group.get)
        names = " and ".join(g.__name__ for g in in_order)
        raise GraphFileError(
            path, first_line_of_group[in_order[1]], f"mixes {names} lines in one graph"
        )
    if not groups:
        first = min(entries[0][0] for entries in lines_by_tag.values())
        tags = " and ".join(sorted(lines_by_tag))
        raise GraphFileError(path, first, f"holds no vertices or edges, only {tags} lines")
    group = groups.pop()

    collected = _Collected()
    for tag, entries in lines_by_tag.items():
        spec = ALL_TAGS[tag]
        if options.identity_information:
            entries = _pad_missing_information(entries, spec)
        rows = to_rows(
            tag, entries, spec.widths, spec.id_columns, checker, spec.widths_without_information
        )
        if rows is not None:
            _convert(spec, rows, options, checker, collected)
    _apply_prior_offsets(collected, checker)
    checker.raise_first()

    sim3_rows = [
        rows
        for rows, *_ in collected.vertices + collected.edges
        if ALL_TAGS[rows.tag].group is Sim3
    ]
    if group is Sim3 and not sim3_rows:
        group = SE3  # every Sim3 line was skipped (lenient): the SE3 lines are the graph
    lifted_scale_information = None
    if group is Sim3:
        lifted_scale_information = _lift_se3_records(collected, options.scale_information)
    skipped_vertices = _skipped_vertex_lines(lines_by_tag, checker)
    graph, without_vertex = _assemble(group, collected, checker, skipped_vertices)
    checker.raise_first()
    tag_counts = Counter()
    for rows, *_ in collected.vertices + collected.edges + collected.priors:
        tag_counts[rows.tag] += len(rows)
    for rows in collected.fixes + collected.equivalences + [r for r, _ in collected.parameters]:
        tag_counts[rows.tag] += len(rows)
    sim3_dialect = None
    if sim3_rows:
        widths = {rows.numbers.shape[1] for rows in sim3_rows}
        sim3_dialect = "a" if widths & {9, 38} else "b"
    file_format = "toro" if any(t in TORO_TAGS for t in lines_by_tag) else "g2o"
    read = ReadResult(
        graph,
        path,
        file_format,
        dict(tag_counts),
        sorted(checker.skipped),
        without_vertex,
        sim3_dialect,
        lifted_scale_information,
    )
    if graph.num_nodes == 0:  # lenient reading skipped every vertex and edge line
        raise GraphFileError(
            path, None, f"holds no vertex or edge that could be read ({read.skipped_report()})"
        )
    return read


def _unknown_tag_reason(tag: str, options: ReadOptions) -> str:
    """Why a line of an unknown tag is refused: a landmark tag is named as one; a line
    that starts with a number is a trajectory's (TUM or KITTI), not a graph's; otherwise, in
    strict mode, --lenient skips such lines."""
    if tag in LANDMARK_TAGS:
        advice = "" if options.lenient else " (--lenient leaves the landmarks out)"
        return f"landmark tag {tag!r}: posegraph optimises poses only{advice}"
    try:
        float(tag)
    except ValueError:
        advice = "" if options.lenient else " (--lenient skips lines it cannot read)"
        return f"unknown tag {tag!r}{advice}"
    return (
        f"unknown tag {tag!r}: a line of numbers, as in a TUM or KITTI trajectory, not a g2o or"
        " TORO graph"
    )


def _skipped_vertex_lines(lines_by_tag: dict[str, list], checker: LineChecker) -> dict[int, int]:
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


def _assemble(group, collected: _Collected, checker: LineChecker, skipped_vertices: dict):
    """The graph of the lines collected, and the ids of its nodes without a vertex value.

    Edges and priors may name nodes without a vertex line only in a file that has none; then
    every node's value is composed along a spanning tree and aligned to the priors. A node
    whose vertex line lenient reading skipped (``skipped_vertices``) keeps its edges, and its
    value is composed from the nodes that have values.
    """
    vertex_ids, vertex_lines = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    values = group.identity((0,))
    if collected.vertices:
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
        vertex_ids, vertex_lines, values = vertex_ids[kept], lines[kept], values[kept]

    salvaged = np.setdiff1d(np.fromiter(skipped_vertices, np.int64), vertex_ids)
    known_ids = np.concatenate([vertex_ids, salvaged])
    check = bool(collected.vertices)
    edges = []
    for rows, measurements, information in collected.edges:
        kept = _filter_known(rows, (0, 1), known_ids, check, checker, skipped_vertices)
        edges.append((rows.ids(0)[kept], rows.ids(1)[kept], measurements[kept], information[kept]))
    priors = []
    for rows, measurements, information in collected.priors:
        kept = _filter_known(rows, (0,), known_ids, check, checker, skipped_vertices)
        priors.append((rows.ids(0)[kept], measurements[kept], information[kept]))

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
    if without_vertex.size:
        known = ~np.isin(graph.node_ids, without_vertex)
        values = spanning_tree_values(graph, known)
        graph.set_values(values if known.any() else align_to_priors(graph, values))
    return graph, without_vertex


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
