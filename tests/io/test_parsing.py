"""Line parsing: byte-order marks, line endings and comments, 64-bit ids, whole-tag parsing against
line-by-line parsing."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.io import GraphFileError, ReadOptions, read_graph, write_graph
from posegraph.io.parsing import (
    LineChecker,
    _rows_from_tokens,
    _uniform_numbers,
    read_tagged_lines,
    to_rows,
)
from posegraph.io.records import ALL_TAGS
from posegraph.io.trajectories import read_trajectory
from posegraph.lie import SE2
from tests.io.helpers import assert_same_graph

from ..conftest import random_graph


def _rows_both_ways(path):
    """Each tag's rows of a file, parsed whole (``to_rows``) and line by line
    (``_rows_from_tokens``), and whether ``to_rows`` could parse the tag's lines whole."""
    by_tag: dict[str, list] = {}
    for number, tag, text in read_tagged_lines(str(path)):
        by_tag.setdefault(tag, []).append((number, text))
    for tag, entries in by_tag.items():
        spec = ALL_TAGS[tag]
        whole = to_rows(
            tag, entries, spec.widths, spec.id_columns, LineChecker(str(path), lenient=True)
        )
        tokens = [(number, text.split()) for number, text in entries]
        by_line = _rows_from_tokens(
            tag,
            tokens,
            spec.widths,
            spec.id_columns,
            LineChecker(str(path), lenient=True),
            frozenset(),
        )
        whole_tag = _uniform_numbers(entries, spec.widths, len(spec.id_columns)) is not None
        yield tag, whole, by_line, whole_tag


def _assert_same_rows(whole, by_line) -> None:
    np.testing.assert_array_equal(whole.line_numbers, by_line.line_numbers)
    np.testing.assert_array_equal(whole.numbers, by_line.numbers)
    np.testing.assert_array_equal(whole.node_ids, by_line.node_ids)


def test_byte_order_mark_line_endings_and_comments(tmp_path):
    """A UTF-8 byte-order mark, CRLF line ends, tabs, and # comments (whole-line or after a
    line's numbers) read as the plain file does."""
    graph = random_graph(SE2, 6, 2, seed=40)
    plain = tmp_path / "plain.g2o"
    write_graph(graph, str(plain))
    lines = plain.read_text().splitlines()
    decorated_lines = ["# exported by a tool", lines[0].replace(" ", "\t")]
    decorated_lines += [f"{line}  # note {k}" for k, line in enumerate(lines[1:])]
    decorated = tmp_path / "decorated.g2o"
    decorated.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(decorated_lines).encode() + b"\r\n")
    assert_same_graph(read_graph(str(decorated)).graph, read_graph(str(plain)).graph)


def test_64_bit_node_ids_are_read_exactly(tmp_path):
    """Ids beyond 2⁵³ (gtsam's symbol keys: 'x' << 56 | index) differ in their last digits,
    which floats cannot hold."""
    keys = [(ord("x") << 56) + k for k in range(3)] + [2**63 - 1]
    path = tmp_path / "keys.g2o"
    path.write_text(
        "".join(f"VERTEX_SE2 {key} {k} 0 0\n" for k, key in enumerate(keys))
        + "".join(
            f"EDGE_SE2 {a} {b} 1 0 0 1 0 0 1 0 1\n"
            for a, b in zip(keys[:-1], keys[1:], strict=True)
        )
    )
    graph = read_graph(str(path)).graph
    assert graph.node_ids.tolist() == keys
    assert graph.node_ids[graph.edges.i].tolist() == keys[:-1]
    assert graph.node_ids[graph.edges.j].tolist() == keys[1:]
    np.testing.assert_array_equal(graph.values.as_matrix()[:, 0, 2], np.arange(4.0))


def test_reading_sphere2500_is_fast_enough_to_matter(shared_dataset):
    """Functional check on the large benchmark file (its speed is in the benchmark script)."""
    result = read_graph(str(shared_dataset("sphere2500.g2o")))
    assert result.tag_counts == {"VERTEX_SE3:QUAT": 2500, "EDGE_SE3:QUAT": 4949}


def test_w10000_with_equiv_lines(gtsam_dataset):
    result = read_graph(str(gtsam_dataset("w10000.graph")))
    assert result.format == "toro"
    assert result.tag_counts == {"VERTEX2": 10000, "EDGE2": 64311, "EQUIV": 5875}
    assert result.graph.equivalences.shape == (5875, 2)


@pytest.mark.parametrize(
    "name", ["w10000.graph", "sphere2500.txt", "Klaus3.g2o", "pose3example-offdiagonal.txt"]
)
def test_whole_tag_parsing_reads_what_line_by_line_parsing_reads(gtsam_dataset, name):
    """``to_rows`` parses a tag's lines in one call of numpy's C reader and falls back to
    parsing them line by line. On real files both give the same numbers, bit for bit."""
    for tag, whole, by_line, whole_tag in _rows_both_ways(gtsam_dataset(name)):
        assert whole_tag or not ALL_TAGS[tag].widths, tag  # FIX lines, of any length: by line
        _assert_same_rows(whole, by_line)


def test_unusual_numbers_read_the_same_both_ways(tmp_path):
    """Tabs, runs of spaces, a form feed between numbers (a blank to g2o's streams too),
    exponents, signs, infinities, a comment after the numbers, ids near 2⁵³ (still exact), and
    an id of 2⁵³ + 1 (parsed exactly, line by line): both ways agree on every line."""
    path = tmp_path / "unusual.g2o"
    path.write_text(
        "VERTEX_SE2\t0\t1e-3  -2.5E+2 +.5\n"
        "VERTEX_SE2 9007199254740991 1\f2 3 # comment\n"
        "VERTEX_SE2 2 -0 0.0 inf\n"
        "VERTEX_SE3:QUAT 7 10 3 0 0 0 0 1\n"
        "VERTEX_SE3:QUAT 9007199254740993 0 0 0 0 0 0 1\n"
        "VERTEX_SE3:QUAT 8 -1e308 1e-320 0 0 0 0 1\n"
    )
    parsed = {tag: rows for tag, *rows in _rows_both_ways(path)}
    assert [whole_tag for *_, whole_tag in parsed.values()] == [True, False]
    for whole, by_line, _ in parsed.values():
        _assert_same_rows(whole, by_line)
    se2 = parsed["VERTEX_SE2"][0]
    np.testing.assert_array_equal(se2.line_numbers, [1, 2])  # line 3's inf is refused
    assert se2.node_ids[:, 0].tolist() == [0, 2**53 - 1]
    assert se2.numbers[0].tolist() == [0, 1e-3, -250.0, 0.5]
    se3 = parsed["VERTEX_SE3:QUAT"][0]
    assert se3.node_ids[:, 0].tolist() == [7, 2**53 + 1, 8]
    assert se3.numbers[0, 1:3].tolist() == [10.0, 3.0]


@pytest.mark.parametrize(
    "number, character",
    [("1_0", "_"), ("\u0663", "\u0663"), ("\uff13", "\uff13"), ("1\u00a02", "\u00a0")],
)
@pytest.mark.parametrize("where", ["value", "id"])
def test_numbers_outside_the_ascii_syntax_are_refused(tmp_path, number, character, where):
    """Python's ``float`` reads "1_0" as 10 and Arabic-Indic or full-width digits as digits,
    and numpy's reader splits at a no-break space; g2o and gtsam read ASCII. Such a line is
    refused naming it and the character, in values and node ids alike, in graph and
    trajectory files."""
    line = f"VERTEX_SE2 {number} 0 0 0" if where == "id" else f"VERTEX_SE2 1 {number} 0 0"
    if where == "id" and character == "\u00a0":
        line = "VERTEX_SE2 1\u00a02 0 0 0"
    path = tmp_path / "odd.g2o"
    path.write_text(f"VERTEX_SE2 0 0 0 0\n{line}\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    assert raised.value.line == 2
    assert f"{character!r} (U+{ord(character):04X}) is outside the ASCII syntax" in str(
        raised.value
    )
    lenient = read_graph(str(path), ReadOptions(lenient=True))
    # Without its id, node 1 has no vertex line: the edge to it is skipped too.
    assert [line for line, _ in lenient.skipped] == ([2] if where == "value" else [2, 3])
    tum = tmp_path / "odd.tum"
    tum.write_text(f"0 0 0 0 0 0 0 1\n1 {number} 0 0 0 0 0 1\n")
    with pytest.raises(GraphFileError, match="outside the ASCII syntax") as raised:
        read_trajectory(str(tum), "tum")
    assert raised.value.line == 2


def test_lines_end_at_newline_alone(tmp_path):
    """Form feed, vertical tab, U+0085, U+2028 and U+2029 do not end a line (``str.splitlines``
    would): an error after them names the line an editor shows, and a comment holding one is
    a comment to its end."""
    header = "VERTEX_SE2 0 0 0 0  # a comment \f VERTEX_SE2 0 x\n"
    for separator in ("\f", "\v", "\x85", "\u2028", "\u2029", "\x1c"):
        path = tmp_path / "separators.g2o"
        path.write_text(
            header
            + f"# note{separator}more note\n"
            + "VERTEX_SE2 1 1 0 0\n"
            + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
            + "EDGE_SE2 0 1 x 0 0 1 0 0 1 0 1\n"
        )
        with pytest.raises(GraphFileError) as raised:
            read_graph(str(path))
        assert raised.value.line == 5, separator
        assert "'x' is not a number" in str(raised.value)
