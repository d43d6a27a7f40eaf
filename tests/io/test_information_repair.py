"""Reading information that is not positive semi-definite: refused with the repair named, or
repaired as ``ReadOptions.repair_information`` says, with the count in ``ReadResult``."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph.checks import information_problems
from posegraph.io import GraphFileError, ReadOptions, read_graph

INFO_SE3 = "100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400"
# cubicle.g2o's kind of line: (z, qx, qy) coupled far beyond the diagonal.
INDEFINITE_SE3 = "100 0 0 0 0 0 100 0 0 0 0 10 84022 132748 0 10 0 0 10 0 400"


def _file(tmp_path):
    path = tmp_path / "indefinite.g2o"
    path.write_text(
        "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
        "VERTEX_SE3:QUAT 2 2 0 0 0 0 0 1\n"
        f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {INFO_SE3}\n"
        f"EDGE_SE3:QUAT 1 2 1 0 0 0 0 0 1 {INDEFINITE_SE3}\n"
        f"EDGE_SE3:QUAT 0 2 2 0 0 0 0 0 1 {INDEFINITE_SE3}\n"
    )
    return str(path)


def test_the_refusal_names_the_repair(tmp_path):
    with pytest.raises(GraphFileError, match="--repair-information psd clips") as raised:
        read_graph(_file(tmp_path))
    assert raised.value.line == 5
    assert "(the first of 2 bad lines found)" in str(raised.value)


@pytest.mark.parametrize("repair, repaired", [("psd", 2), ("isotropic", 3)])
def test_repaired_information_reads_and_is_counted(tmp_path, repair, repaired):
    read = read_graph(_file(tmp_path), ReadOptions(repair_information=repair))
    assert read.repaired_information == repaired and read.graph.num_edges == 3
    assert not information_problems(read.graph.edges.information)[0].any()
    first = read.graph.edges.information[0]
    if repair == "psd":  # a matrix that needed none is kept
        np.testing.assert_array_equal(first, np.diag([100.0] * 3 + [400.0] * 3))
    else:
        np.testing.assert_allclose(first, np.diag([100.0] * 3 + [400.0] * 3), rtol=1e-12)


def test_lenient_reading_groups_the_refusals_as_one_kind(tmp_path):
    read = read_graph(_file(tmp_path), ReadOptions(lenient=True))
    [(why, count, line)] = read.skipped_by_reason()
    assert count == 2 and line == 5 and "not positive semi-definite" in why


def test_an_unknown_repair_is_refused():
    with pytest.raises(ValueError, match="repair_information must be one of psd, isotropic"):
        ReadOptions(repair_information="clip")
