"""Every malformed file gives its own clear error naming the file and line."""

from __future__ import annotations

import pytest

from posegraph.io import GraphFileError, read_graph
from posegraph.trajectory_io import read_trajectory

from .malformed import MALFORMED


def write_case(tmp_path, name, content):
    path = tmp_path / f"{name}.g2o"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    return path


def test_corpus_is_large_and_distinct():
    assert len(MALFORMED) >= 20
    assert len({name for name, *_ in MALFORMED}) == len(MALFORMED)


@pytest.mark.parametrize("name, content, line, words", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_is_rejected_with_file_and_line(tmp_path, name, content, line, words):
    path = write_case(tmp_path, name, content)
    with pytest.raises(GraphFileError) as caught:
        read_graph(str(path))
    error = caught.value
    assert error.path == str(path)
    assert error.line == line
    assert words in error.message
    where = f"{path}:{line}" if line is not None else str(path)
    assert str(error).startswith(f"{where}: ")
    assert "\n" not in str(error)


@pytest.mark.parametrize(
    "quaternion, words",
    [("0 0 0 0", "quaternion has zero norm"), ("0 1e200 0 1", "quaternion's norm overflows")],
)
def test_tum_quaternion_that_is_no_rotation_is_rejected(tmp_path, quaternion, words):
    path = tmp_path / "poses.tum"
    path.write_text(f"0.0 1 2 3 0 0 0 1\n0.1 1 2 3 {quaternion}\n")
    with pytest.raises(GraphFileError, match=rf"poses\.tum:2: {words}"):
        read_trajectory(str(path), "tum")
