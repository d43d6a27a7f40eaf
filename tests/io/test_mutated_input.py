"""Small valid files of every tag, mutated at random (a token replaced, dropped or inserted, a line
duplicated or deleted, a tag swapped): whatever the damage, reading either succeeds or raises a
``GraphFileError`` on one line that names the file and, unless the fault is the whole file's
(nothing readable, say), a line it has; lenient reading skips the line strict reading stopped at,
and a graph that reads cleanly optimises or is refused with a ValueError."""

from __future__ import annotations

import numpy as np
import pytest

import posegraph
from posegraph.io import GraphFileError, ReadOptions, read_graph

hypothesis = pytest.importorskip("hypothesis")
st = hypothesis.strategies

INFO_SE2 = "100 0 0 100 0 1000"
INFO_SE3 = "100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400"
INFO_SIM3 = "100 0 0 0 0 0 0 100 0 0 0 0 0 100 0 0 0 0 400 0 0 0 400 0 0 400 0 50"
INFO_TORO2 = "100 0 100 1000 0 0"
INFO_TORO3 = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1"

VALID_FILES = {
    "se2.g2o": f"""VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0.1
VERTEX_SE2 2 2 0.1 0.2
VERTEX_SE2 3 2 1 1.6
EDGE_SE2 0 1 1 0 0.1 {INFO_SE2}
EDGE_SE2 1 2 1 0.1 0.1 {INFO_SE2}
EDGE_SE2 2 3 1 0 1.5 {INFO_SE2}
EDGE_SE2 3 0 2 1 1.6 100 1 0 100 0 1000
EDGE_PRIOR_SE2 0 0 0 0 10 0 0 10 0 10
FIX 0
""",
    "se3.g2o": f"""VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0.0998 0.995
VERTEX_SE3:QUAT 2 2 0.1 0 0 0 0.2 0.98
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SE3:QUAT 1 2 1 0.1 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SE3:QUAT 2 0 -2 0 0 0 0 -0.2 0.98 {INFO_SE3}
PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1
EDGE_SE3_PRIOR 1 0 1 0 0 0 0 0.1 0.995 {INFO_SE3}
""",
    "sim3a.g2o": f"""VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1
VERTEX_SIM3:EXPMAP 1 0 0 0.05 0.999 -1 0 0 0.9
VERTEX_SIM3:EXPMAP 2 0 0 0.1 0.995 -2 0.1 0 0.8
EDGE_SIM3:EXPMAP 0 1 0 0 0.05 0.999 1 0 0 1.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 1 2 0 0 0.05 0.999 1 0.1 0 1.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 2 0 0 0 -0.1 0.995 2 0 0 1.2 {INFO_SIM3}
""",
    "sim3b.g2o": f"""VERTEX_SIM3:EXPMAP 0 0 0 0 0 0 0 0 500 500 320 240
VERTEX_SIM3:EXPMAP 1 1 0 0 0 0 0.1 0.1 500 500 320 240
VERTEX_SIM3:EXPMAP 2 2 0 0 0 0 0.2 0.2 500 500 320 240
EDGE_SIM3:EXPMAP 0 1 1 0 0 0 0 0.1 0.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 1 2 1 0 0 0 0 0.1 0.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 2 0 -2 0 0 0 0 -0.2 -0.2 {INFO_SIM3}
""",
    "toro2.graph": f"""VERTEX2 0 0 0 0
VERTEX2 1 1 0 0
VERTEX2 2 2 0 0
EDGE2 0 1 1 0 0 {INFO_TORO2}
EDGE2 1 2 1 0 0 {INFO_TORO2}
EDGE2 2 0 -2 0 0 {INFO_TORO2}
EQUIV 0 0
""",
    "toro3.graph": f"""VERTEX3 0 0 0 0 0 0 0
VERTEX3 1 1 0 0 0 0 0
EDGE3 0 1 1 0 0 0 0 0.1 {INFO_TORO3}
EDGE3 1 0 -1 0 0 0 0 -0.1 {INFO_TORO3}
""",
}
TAGS = sorted({line.split()[0] for text in VALID_FILES.values() for line in text.splitlines()})
ODD_TOKENS = [
    "nan", "inf", "-inf", "1e400", "-1e400", "1e308", "1e-320", "-0", "0", "-1", "1.5", "2", "7",
    "99999999999999999999", "0x10", "1,5", "abc", "#", "١",
]  # fmt: skip


@st.composite
def mutated_files(draw) -> tuple[str, str]:
    """(file name, text): one of ``VALID_FILES`` with one to three mutations."""
    name = draw(st.sampled_from(sorted(VALID_FILES)))
    lines = [line.split() for line in VALID_FILES[name].splitlines()]
    for _ in range(draw(st.integers(1, 3))):
        if not lines:
            lines.append([])
        k = draw(st.integers(0, len(lines) - 1))
        tokens = lines[k]
        position = draw(st.integers(0, len(tokens)))
        kind = draw(st.sampled_from(["replace", "drop", "insert", "duplicate", "delete", "tag"]))
        if kind == "insert" or (kind in ("replace", "drop") and position == len(tokens)):
            tokens.insert(position, draw(st.sampled_from(ODD_TOKENS)))
        elif kind == "replace":
            tokens[position] = draw(st.sampled_from(ODD_TOKENS))
        elif kind == "drop":
            del tokens[position]
        elif kind == "duplicate":
            lines.insert(position % (len(lines) + 1), list(tokens))
        elif kind == "delete":
            del lines[k]
        elif tokens:
            tokens[0] = draw(st.sampled_from(TAGS))
    return name, "".join(" ".join(tokens) + "\n" for tokens in lines)


@pytest.mark.parametrize("name", sorted(VALID_FILES))
def test_the_files_before_damage_read(tmp_path, name):
    """The mutations start from files that read, with every line."""
    path = tmp_path / name
    path.write_text(VALID_FILES[name])
    result = read_graph(str(path))
    assert sum(result.tag_counts.values()) == len(VALID_FILES[name].splitlines())
    assert result.graph.num_edges > 0


def _read(path: str, options: ReadOptions):
    try:
        return read_graph(path, options)
    except GraphFileError as error:
        return error


@hypothesis.settings(max_examples=300, deadline=None, derandomize=True, database=None)
@hypothesis.given(mutated_files())
def test_a_damaged_file_reads_or_is_refused_naming_one_of_its_lines(tmp_path_factory, case):
    name, text = case
    path = str(tmp_path_factory.mktemp("mutated") / name)
    with open(path, "w") as file:
        file.write(text)
    lines = len(text.splitlines())
    strict, lenient = _read(path, ReadOptions()), _read(path, ReadOptions(lenient=True))
    for outcome in (strict, lenient):
        if isinstance(outcome, GraphFileError):
            assert outcome.path == path
            assert outcome.line is None or 1 <= outcome.line <= lines
            assert "\n" not in str(outcome)
    if isinstance(strict, GraphFileError):
        if not isinstance(lenient, GraphFileError) and strict.line is not None:
            assert strict.line in [line for line, _ in lenient.skipped], strict.message
        return
    assert not isinstance(lenient, GraphFileError) and lenient.skipped == []
    try:
        result = posegraph.optimize(strict.graph)
    except ValueError:  # a graph the solver refuses, with its reason (tests/test_cli.py)
        return
    assert np.isfinite(result.summary.final_error)
