"""Read g2o and TORO pose-graph files into a ``PoseGraph``, strictly or leniently."""

from __future__ import annotations

import dataclasses
import re
from collections import Counter

import numpy as np

from ..graph import PoseGraph
from ..lie import SE3, Sim3
from .assembly import SE3Lines, assemble, skipped_vertex_lines
from .errors import GraphFileError
from .options import ReadOptions
from .parsing import LineChecker, Rows, paused_garbage_collection, read_tagged_lines, to_rows
from .records import (
    ALL_TAGS,
    Collected,
    apply_prior_offsets,
    convert_rows,
    embed_se3_records,
    pad_missing_information,
)
from .tags import LANDMARK_TAGS, TORO_TAGS


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
    """Ids of nodes that had no vertex line (or only ones that lenient reading skipped): they
    have no value (``load_graph`` composes them)."""
    sim3_dialect: str | None
    """"a" (element) or "b" (log of the inverse) for Sim3 files."""
    se3_lines: SE3Lines | None = None
    """In a file mixing SE3 and Sim3 lines, which edges and priors were SE3 lines: read at
    scale 1 with no information on log-scale (``load_graph`` lifts them); None otherwise."""
    repaired_information: int = 0
    """Information matrices changed by ``ReadOptions.repair_information``."""
    rejected: tuple[np.ndarray, np.ndarray] | None = None
    """Masks over the graph's between edges and priors of those whose lines a robust run
    marked rejected (``parsing.REJECTED_PREFIX``); None if no line is marked. They are in the
    graph: leave them out to reproduce that run (``PoseGraph.with_edges``)."""
    lifted_scale_information: float | None = None
    """The information on log-scale that ``load_graph`` gave the SE3 lines of a file mixing
    SE3 and Sim3 (``ReadOptions.scale_information``, or its default); None if none were
    lifted."""

    def skipped_by_reason(self) -> list[tuple[str, int, int]]:
        """(reason, how many lines, the first one's number) of the skipped lines, most frequent
        kind first (ties in the order of their first line); reasons that differ only in their
        numbers are one kind, named by its first line's reason."""
        return skipped_by_reason(self.skipped)

    def skipped_report(self, reasons: int = 3) -> str:
        """The report "N line(s) skipped: k × reason (first at line L); …" of the skipped lines,
        naming the ``reasons`` most frequent reasons."""
        return skipped_report(self.skipped, reasons)


_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?")
"""A number in a reason (a node id, λ_min, a count): reasons that differ only there are one
kind."""


def skipped_by_reason(skipped: list[tuple[int, str]]) -> list[tuple[str, int, int]]:
    """``ReadResult.skipped_by_reason`` of (line, reason) pairs in line order: reasons that
    differ only in their numbers are counted together, under the first line's."""
    first: dict[str, tuple[int, str]] = {}
    counts: Counter = Counter()
    for line, why in skipped:
        kind = _NUMBER.sub("#", why)
        first.setdefault(kind, (line, why))
        counts[kind] += 1
    return [(first[kind][1], count, first[kind][0]) for kind, count in counts.most_common()]


def skipped_report(skipped: list[tuple[int, str]], reasons: int = 3) -> str:
    """``ReadResult.skipped_report`` of (line, reason) pairs in line order."""
    grouped = skipped_by_reason(skipped)
    named = "; ".join(
        f"{count} × {why} (first at line {line})" for why, count, line in grouped[:reasons]
    )
    more = "; …" if len(grouped) > reasons else ""
    return f"{len(skipped)} line(s) skipped: {named}{more}"


@paused_garbage_collection()
def read_graph(path: str, options: ReadOptions | None = None) -> ReadResult:
    """Read a g2o or TORO file (told apart by their tags).

    Raises ``GraphFileError`` naming ``file:line`` and the problem. The checks run in three
    stages: the tags, each line's numbers, then what lines refer to (a vertex defined again,
    an edge to a node without a vertex line). Strict reading stops at the first stage that
    finds bad lines and names the earliest of them, with how many it found. The graph is what
    the file says: nodes that appear only in edges are created without a value, and the SE3
    lines of a file mixing SE3 and Sim3 are Sim3 ones of scale 1 with no information on
    log-scale (``load_graph`` composes the values and lifts those lines).
    """
    path = str(path)
    options = ReadOptions() if options is None else options
    checker = LineChecker(path, options.lenient)
    rejected_lines: set[int] = set()
    lines_by_tag = _lines_by_tag(path, options, checker, rejected_lines)
    group = _group_of(path, lines_by_tag, checker)
    collected = _collected(lines_by_tag, options, checker)

    sim3_rows = [
        rows
        for rows, *_ in collected.vertices + collected.edges
        if ALL_TAGS[rows.tag].group is Sim3
    ]
    if group is Sim3 and not sim3_rows:
        group = SE3  # every Sim3 line was skipped (lenient): the SE3 lines are the graph
    if group is Sim3:
        embed_se3_records(collected)
    skipped_vertices = skipped_vertex_lines(lines_by_tag, checker)
    graph, without_vertex, se3_lines, rejected = assemble(
        group, collected, checker, skipped_vertices, rejected_lines
    )
    checker.raise_first()
    read = ReadResult(
        graph,
        path,
        "toro" if any(t in TORO_TAGS for t in lines_by_tag) else "g2o",
        _tag_counts(collected),
        sorted(checker.skipped),
        without_vertex,
        _sim3_dialect(sim3_rows),
        se3_lines,
        collected.repaired,
        rejected,
    )
    if graph.num_nodes == 0:  # lenient reading skipped every vertex and edge line
        raise GraphFileError(
            path, None, f"holds no vertex or edge that could be read ({read.skipped_report()})"
        )
    return read


def _collected(lines_by_tag: dict[str, list], options: ReadOptions, checker) -> Collected:
    """Each tag's lines checked and converted (``convert_rows``), priors' offsets applied;
    strict reading stops here at the first bad line."""
    collected = Collected()
    for tag, entries in lines_by_tag.items():
        spec = ALL_TAGS[tag]
        if options.identity_information:
            entries = pad_missing_information(entries, spec)
        rows = to_rows(
            tag, entries, spec.widths, spec.id_columns, checker, spec.widths_without_information
        )
        if rows is not None:
            convert_rows(spec, rows, options, checker, collected)
    apply_prior_offsets(collected, checker)
    checker.raise_first()
    return collected


def _lines_by_tag(
    path: str, options: ReadOptions, checker: LineChecker, rejected: set[int]
) -> dict[str, list]:
    """The file's (line number, text) pairs by tag, lines marked rejected among them (their
    numbers put in ``rejected``); unknown tags refused (strict) or skipped."""
    lines_by_tag: dict[str, list] = {}
    for number, tag, text in read_tagged_lines(path, rejected):
        if tag not in ALL_TAGS:
            checker.fail(number, _unknown_tag_reason(tag, options))
            continue
        lines_by_tag.setdefault(tag, []).append((number, text))
    checker.raise_first()
    if not lines_by_tag:
        found = skipped_report(sorted(checker.skipped)) if checker.skipped else "is the file empty?"
        raise GraphFileError(path, None, f"holds no vertices or edges ({found})")
    return lines_by_tag


def _family(group):
    """SE3 and Sim3 lines make one graph (SE3 odometry with Sim3 loop closures)."""
    return SE3 if group is Sim3 else group


def _group_of(path: str, lines_by_tag: dict[str, list], checker: LineChecker):
    """The one group of the file's lines: Sim3 for SE3 odometry with Sim3 loop closures. A
    file that mixes others is refused, naming the first line of a group that is not the most
    frequent; lenient
    reading keeps the group of most lines and skips the others' lines (taken out of
    ``lines_by_tag``). A file of no vertex or edge lines is refused."""
    first_line: dict = {}
    count: Counter = Counter()
    for tag, entries in lines_by_tag.items():
        family = _family(ALL_TAGS[tag].group)
        if family is not None:
            first_line[family] = min(first_line.get(family, entries[0][0]), entries[0][0])
            count[family] += len(entries)
    if not first_line:
        first = min(entries[0][0] for entries in lines_by_tag.values())
        tags = " and ".join(sorted(lines_by_tag))
        raise GraphFileError(path, first, f"holds no vertices or edges, only {tags} lines")
    in_order = sorted(first_line, key=first_line.get)
    kept = max(in_order, key=count.get)  # the first of the most frequent
    if len(in_order) > 1 and not checker.lenient:
        other = next(family for family in in_order if family is not kept)
        raise GraphFileError(
            path,
            first_line[other],
            f"mixes {other.__name__} and {kept.__name__} lines in one graph: a"
            f" {other.__name__} line among {count[kept]} {kept.__name__} lines (--lenient skips"
            " the lines of the other groups)",
        )
    for tag in list(lines_by_tag):
        family = _family(ALL_TAGS[tag].group)
        if family is not None and family is not kept:
            for number, _ in lines_by_tag.pop(tag):
                checker.fail(number, f"{tag}: a {family.__name__} line in a {kept.__name__} graph")
    groups = {ALL_TAGS[tag].group for tag in lines_by_tag} - {None}
    return Sim3 if Sim3 in groups else kept


def _tag_counts(collected: Collected) -> dict[str, int]:
    """Lines read per tag."""
    tag_counts = Counter()
    for rows, *_ in collected.vertices + collected.edges + collected.priors:
        tag_counts[rows.tag] += len(rows)
    for rows in collected.fixes + collected.equivalences + [r for r, _ in collected.parameters]:
        tag_counts[rows.tag] += len(rows)
    return dict(tag_counts)


def _sim3_dialect(sim3_rows: list[Rows]) -> str | None:
    """ "a" (the element, 9 or 38 numbers a line) or "b" (log of the inverse); None without Sim3."""
    if not sim3_rows:
        return None
    widths = {rows.numbers.shape[1] for rows in sim3_rows}
    return "a" if widths & {9, 38} else "b"


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
        " TORO graph ('posegraph convert TRAJECTORY graph.g2o' makes a graph of a trajectory)"
    )
