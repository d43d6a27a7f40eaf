"""Every malformed file gives its own clear error naming the file and line."""

from __future__ import annotations

import pytest

from posegraph.io import GraphFileError, read_graph
from posegraph.io.trajectories import read_trajectory

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


GOOD_TUM = "0.0 1 2 3 0 0 0 1\n"
GOOD_KITTI = "1 0 0 5 0 1 0 6 0 0 1 7\n"


@pytest.mark.parametrize(
    "file_format, bad, words",
    [
        ("tum", "0.2 1 2 3 0 0 1", "TUM lines have 8 numbers, found 7"),
        ("tum", "0.2 1 2 three 0 0 0 1", "a value is not a number"),
        ("tum", "0.2 1 nan 3 0 0 0 1", "NaN or infinite value"),
        ("kitti", "1 0 0 5 0 1 0 6 0 0 1 inf", "NaN or infinite value"),
        ("kitti", "1 0 0 5 0 1 0 6 0 0 1 7 8", "KITTI lines have 12 numbers, found 13"),
    ],
)
def test_trajectory_line_that_is_bad_is_named(tmp_path, file_format, bad, words):
    """Trajectory lines are converted at once; a bad one (here the third line, after a comment)
    is still named, with what is wrong."""
    good = GOOD_TUM if file_format == "tum" else GOOD_KITTI
    path = tmp_path / f"poses.{file_format}"
    path.write_text(good + "# a comment\n" + bad + "\n" + good)
    with pytest.raises(GraphFileError, match=rf"poses\.{file_format}:3: {words}"):
        read_trajectory(str(path), file_format)


def test_trajectory_names_the_first_bad_line_whatever_is_wrong_with_the_others(tmp_path):
    path = tmp_path / "poses.tum"
    path.write_text(GOOD_TUM + "0.1 1 inf 3 0 0 0 1\n0.2 1 2 3 0 0 1\n0.3 x 2 3 0 0 0 1\n")
    with pytest.raises(GraphFileError, match=r"poses\.tum:2: NaN or infinite value"):
        read_trajectory(str(path), "tum")
