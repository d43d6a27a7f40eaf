"""Numbers that double precision cannot carry through are refused where they enter, naming the
line; what is written is checked as formatted; one stray line of another group is skipped by
lenient reading."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.graph import PoseGraph
from posegraph.io import GraphFileError, ReadOptions, load_graph, read_graph, write_graph
from posegraph.lie import SE2, Sim3
from posegraph.problem.factors import chi2
from posegraph.solvers import solve

from ..conftest import random_graph


def _sim3_file(tmp_path, line: int, column: int, number: str):
    """A Sim3 graph in dialect a (a vertex's scale is its 9th number, an edge's inverse scale
    its 10th) with one number of one line replaced."""
    path = tmp_path / "sim3.g2o"
    write_graph(random_graph(Sim3, 4, 2, seed=3), str(path))
    lines = path.read_text().splitlines()
    fields = lines[line - 1].split()
    fields[column] = number
    lines[line - 1] = " ".join(fields)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    "line, column, number",
    [
        (5, 10, "1e-160"),  # an edge's scale e^368: Sim3.log overflowed, and -o wrote nan
        (5, 10, "1e60"),  # e^-138
        (2, 9, "1e-300"),  # a vertex's: "initial error nan" with exit 0
        (2, 9, "1e50"),
    ],
)
def test_a_scale_beyond_e100_is_refused_naming_its_line(tmp_path, line, column, number):
    path = _sim3_file(tmp_path, line, column, number)
    with pytest.raises(GraphFileError, match="a scale out of range") as raised:
        read_graph(str(path))
    assert raised.value.line == line
    lenient = load_graph(str(path), ReadOptions(lenient=True))
    assert [skipped for skipped, _ in lenient.skipped][0] == line
    graph = lenient.graph
    assert np.isfinite(chi2(graph.values, graph.edges, graph.priors))


def test_scales_within_the_range_are_read_and_optimised(tmp_path):
    path = _sim3_file(tmp_path, 5, 10, "1e-40")  # e^92
    graph = read_graph(str(path)).graph
    result = solve(graph)
    assert np.isfinite(result.summary.final_error) and np.isfinite(result.values.log()).all()


def test_the_library_refuses_elements_out_of_range_as_the_reader_does():
    graph = PoseGraph(Sim3)
    far = Sim3.exp(np.array([0, 0, 0, 0, 0, 0, 120.0]))
    with pytest.raises(ValueError, match="a scale out of range"):
        graph.add_nodes([0], far[None])
    graph.add_nodes([0, 1], Sim3.identity((2,)))
    with pytest.raises(ValueError, match="a scale out of range"):
        graph.add_edges([0], [1], far[None], np.eye(7))


def test_the_writer_checks_the_numbers_it_formats(tmp_path):
    """Finite pose matrices can still give NaN once formatted (the logarithm of a Sim3 of scale
    e^400, which dialect b writes): nothing is written."""
    graph = random_graph(Sim3, 4, 1, seed=5)
    far = Sim3.exp(np.array([0, 0, 0, 0, 0, 0, 400.0]))
    with np.errstate(all="ignore"):
        assert np.isfinite(far.as_matrix()).all() and not np.isfinite(far.log()).all()
    graph.set_values(graph.values.set_at(2, far), check=False)  # as a diverged run could
    path = tmp_path / "out.g2o"
    with pytest.raises(ValueError, match=r"out.g2o: not written: 1 line\(s\) would hold NaN"):
        write_graph(graph, str(path), sim3_dialect="b")
    assert not path.exists()


def _refused_line(tmp_path, text: str, match: str) -> int:
    """The line that strict reading names, refusing ``text`` (written to refused.g2o) with
    ``match``."""
    path = tmp_path / "refused.g2o"
    path.write_text(text)
    with pytest.raises(GraphFileError, match=match) as raised:
        read_graph(str(path))
    return raised.value.line


def test_a_prior_whose_numbers_overflow_is_refused_naming_its_line(tmp_path):
    """Edges had this check; priors surfaced the overflow later, with no line, or as an
    "initial error inf" with exit 0."""
    text = (
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
        "EDGE_PRIOR_SE2 1 1e200 0 0 1 0 0 1 0 1\n"
    )
    assert _refused_line(tmp_path, text, "the prior's translation weighed by") == 4
    graph = PoseGraph(SE2)
    graph.add_nodes([0], SE2.identity((1,)))
    with pytest.raises(ValueError, match="the prior on node 0: its translation weighed"):
        graph.add_priors([0], SE2.from_xytheta(np.array([[1e200, 0, 0]])), np.eye(3))


def test_lenient_reading_skips_a_stray_line_of_another_group(tmp_path):
    """Strict reading names the stray line (the minority group's), lenient reading keeps the
    group of most lines and reports the others as skipped."""
    path = tmp_path / "stray.g2o"
    write_graph(random_graph(SE2, 6, 2, seed=9), str(path))
    lines = path.read_text().splitlines()
    lines.insert(3, "VERTEX_SE3:QUAT 99 0 0 0 0 0 0 1")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(GraphFileError, match="mixes SE3 and SE2 lines") as raised:
        read_graph(str(path))
    assert raised.value.line == 4
    read = read_graph(str(path), ReadOptions(lenient=True))
    assert read.graph.group is SE2 and read.graph.num_nodes == 6
    assert read.skipped == [(4, "VERTEX_SE3:QUAT: a SE3 line in a SE2 graph")]


def test_an_edge_whose_error_at_the_file_values_overflows_is_refused(tmp_path):
    """A vertex at 1e200 is finite, but its edges' errors overflow: ``info`` said "initial
    error inf" with exit 0. The edge is refused naming its line; lenient reading skips it."""
    text = (
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1e200 0 0\nVERTEX_SE2 2 2 0 0\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
        "EDGE_SE2 0 2 2 0 0 1 0 0 1 0 1\n"
    )
    assert _refused_line(tmp_path, text, "its error at the file's values overflows") == 4
    read = read_graph(str(tmp_path / "refused.g2o"), ReadOptions(lenient=True))
    assert [line for line, _ in read.skipped] == [4] and read.graph.num_edges == 1
    graph = read.graph
    assert np.isfinite(chi2(graph.values, graph.edges, graph.priors))
