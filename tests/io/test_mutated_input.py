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
from posegraph.io.parsing import REJECTED_PREFIX
from tests.soak.soak import GRAPH_FILES

hypothesis = pytest.importorskip("hypothesis")
st = hypothesis.strategies

VALID_FILES = GRAPH_FILES
TAGS = sorted(
    {
        line.split()[0]
        for text in VALID_FILES.values()
        for line in text.split("\n")
        if line[:1].isalpha()
    }
)
ODD_TOKENS = [
    "nan", "inf", "-inf", "1e400", "-1e400", "1e308", "1e-320", "-0", "0", "-1", "1.5", "2", "7",
    "99999999999999999999", "0x10", "1,5", "abc", "#", "١",
]  # fmt: skip


@st.composite
def mutated_files(draw) -> tuple[str, str]:
    """(file name, text): one of ``VALID_FILES`` with one to three mutations."""
    name = draw(st.sampled_from(sorted(VALID_FILES)))
    lines = [line.split() for line in VALID_FILES[name].split("\n") if line[:1].isalpha()]
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
    """The mutations start from files that read, with every line (a comment holding a form
    feed or U+2028 is one line; a line marked rejected is read, as rejected)."""
    path = tmp_path / name
    path.write_text(VALID_FILES[name])
    result = read_graph(str(path))
    tagged = [
        line
        for line in VALID_FILES[name].split("\n")
        if line[:1].isalpha() or line.startswith(REJECTED_PREFIX)
    ]
    assert sum(result.tag_counts.values()) == len(tagged)
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
