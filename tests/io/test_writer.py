"""Writing g2o and TORO: exact round trips, what cannot be written, atomic writes."""

from __future__ import annotations

import gc
import os
import stat

import numpy as np
import pytest

from posegraph.io import GraphFileError, ReadOptions, read_graph, write_graph
from posegraph.io.trajectories import Trajectory, as_se3, write_trajectory
from posegraph.lie import SE2, SE3, Sim3
from tests.io.helpers import assert_same_graph

from ..conftest import random_graph


def _round_trip(graph, path, **write_options):
    write_graph(graph, str(path), **write_options)
    options = ReadOptions(
        g2o_rotation_information=write_options.get("g2o_rotation_information", False)
    )
    return read_graph(str(path), options)


# Numbers are printed with repr (shortest exact form), so a read → write → read round trip
# reproduces every number bit for bit; SE3 rotations pass through quaternion → matrix →
# quaternion, which is exact only to a few ulps.
ROUND_TRIP_ATOL = {SE2: 0.0, SE3: 1e-15}


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_g2o_round_trip_is_exact_to_printed_precision(group, tmp_path):
    graph = random_graph(group, 9, 5, seed=31, priors=2)
    graph.fix(graph.node_ids[[1, 4]])
    first = _round_trip(graph, tmp_path / "a.g2o").graph
    assert_same_graph(first, graph, atol=1e-12)
    second = _round_trip(first, tmp_path / "b.g2o").graph
    assert_same_graph(second, first, atol=ROUND_TRIP_ATOL[group])
    if group is SE2:
        assert (tmp_path / "a.g2o").read_text() == (tmp_path / "b.g2o").read_text()


def test_se2_numbers_are_written_back_as_read(tmp_path):
    text = (
        "VERTEX_SE2 0 0.5 -2.25 -0.00818381\n"
        "VERTEX_SE2 1 1.5 0.2 1e-10\n"
        "EDGE_SE2 0 1 1.0 2.47 -3.1 100.0 0.0 0.0 100.0 0.0 400.0\n"
    )
    source, written = tmp_path / "a.g2o", tmp_path / "b.g2o"
    source.write_text(text)
    write_graph(read_graph(str(source)).graph, str(written))
    assert [float(x) for x in written.read_text().split() if x[0] in "-.0123456789"] == [
        float(x) for x in text.split() if x[0] in "-.0123456789"
    ]


def test_poses_that_are_not_finite_are_not_written(tmp_path):
    graph = random_graph(SE3, 5, 2, seed=8)
    diverged = graph.values.set_at(3, SE3(np.full((3, 3), np.nan), np.zeros(3)))
    graph.set_values(diverged, check=False)  # as a diverged solver would leave them
    for path in (tmp_path / "diverged.g2o", tmp_path / "diverged.tum"):
        with pytest.raises(ValueError, match=r"not written: 1 of 5 poses are not finite"):
            if path.suffix == ".g2o":
                write_graph(graph, str(path))
            else:
                write_trajectory(Trajectory(graph.node_ids, graph.values), str(path), "tum")
        assert not path.exists()


def test_negative_zero_is_written_as_zero(tmp_path):
    source, written, tum = tmp_path / "a.g2o", tmp_path / "b.g2o", tmp_path / "b.tum"
    source.write_text("VERTEX_SE2 0 -0.0 0.0 -0.0\nVERTEX_SE2 1 1.0 -0.0 0.0\n")
    graph = read_graph(str(source)).graph
    write_graph(graph, str(written))
    write_trajectory(Trajectory(graph.node_ids, as_se3(graph.values)), str(tum), "tum")
    for path in (written, tum):
        assert "-0.0" not in path.read_text().split()


@pytest.mark.parametrize("dialect", ["a", "b"])
def test_sim3_round_trip_in_both_dialects(dialect, tmp_path):
    graph = random_graph(Sim3, 9, 5, seed=32)
    result = _round_trip(graph, tmp_path / "s.g2o", sim3_dialect=dialect)
    assert result.sim3_dialect == dialect
    assert result.tag_counts == {"VERTEX_SIM3:EXPMAP": 9, "EDGE_SIM3:EXPMAP": len(graph.edges)}
    assert_same_graph(result.graph, graph, atol=1e-10)


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_toro_round_trip(group, tmp_path):
    graph = random_graph(group, 9, 5, seed=34)
    graph.equivalences = np.array([[graph.node_ids[3], graph.node_ids[1]]])
    first = _round_trip(graph, tmp_path / "a.graph")
    assert first.format == "toro"
    assert_same_graph(first.graph, graph, atol=1e-12)
    second = _round_trip(first.graph, tmp_path / "b.graph").graph
    assert_same_graph(second, first.graph, atol=ROUND_TRIP_ATOL[group])


@pytest.mark.parametrize("name", ["out.g2o", "out.graph"])
def test_negative_node_ids_are_not_written_to_graph_files(name, tmp_path):
    """A graph's ids may be negative; the files hold 0 to 2⁶³ − 1, the ids the reader takes,
    so the writer refuses rather than write a file that nothing reads back."""
    graph = random_graph(SE2, 4, 1, seed=43)
    graph.add_node(-3, SE2.identity())
    graph.add_edge(graph.node_ids[0], -3, SE2.identity(), np.eye(3))
    with pytest.raises(ValueError, match="hold node ids 0 to 2⁶³ − 1, not -3"):
        write_graph(graph, str(tmp_path / name))
    assert list(tmp_path.iterdir()) == []
    graph.remove_edges([graph.num_edges - 1])
    kept = graph.subgraph(graph.node_ids >= 0)
    write_graph(kept, str(tmp_path / name))
    assert read_graph(str(tmp_path / name)).graph.num_nodes == 4


def test_writes_are_atomic_and_leave_no_temporary_files(tmp_path):
    graph = random_graph(SE3, 5, 2, seed=39)
    target = tmp_path / "out.g2o"
    target.write_text("previous content\n")
    write_graph(graph, str(target))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.g2o"]
    assert target.read_text().startswith("VERTEX_SE3:QUAT")
    with pytest.raises(ValueError):
        write_graph(random_graph(Sim3, 3, 0, seed=40), str(tmp_path / "x.graph"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.g2o"]


def test_written_files_get_the_usual_permissions_and_errors_name_the_target(tmp_path):
    """``mkstemp`` makes owner-only files; the output gets the umask's mode when new and keeps
    its mode when replaced; a read-only one is not replaced. A failure names the file asked
    for, not the temporary."""
    graph = random_graph(SE2, 4, 1, seed=41)
    umask = os.umask(0o022)
    try:
        write_graph(graph, str(tmp_path / "new.g2o"))
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "new.g2o").stat().st_mode) == 0o644
    kept = tmp_path / "kept.g2o"
    kept.write_text("old\n")
    kept.chmod(0o640)
    write_graph(graph, str(kept))
    assert stat.S_IMODE(kept.stat().st_mode) == 0o640
    missing = tmp_path / "no" / "such" / "out.g2o"
    with pytest.raises(OSError) as raised:
        write_graph(graph, str(missing))
    assert raised.value.filename == str(missing)
    written = kept.read_text()
    kept.chmod(0o444)  # read-only: refused, for root too, though the rename would succeed
    with pytest.raises(PermissionError, match="read-only") as raised:
        write_graph(random_graph(SE2, 4, 1, seed=42), str(kept))
    assert raised.value.filename == str(kept) and kept.read_text() == written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.g2o", "new.g2o"]


@pytest.mark.parametrize("enabled", [True, False])
def test_reading_and_writing_leave_the_garbage_collector_as_they_found_it(tmp_path, enabled):
    """The reader and the writer pause Python's cyclic garbage collector while they parse or
    format (``posegraph.io.parsing.paused_garbage_collection``), and restore its state after a
    file that reads, after one that is refused, and after writing."""
    good, bad = tmp_path / "good.g2o", tmp_path / "bad.g2o"
    good.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    bad.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 zero 1 0 0 1 0 1\n")
    (gc.enable if enabled else gc.disable)()
    try:
        assert read_graph(str(good)).graph.num_edges == 1
        assert gc.isenabled() == enabled
        with pytest.raises(GraphFileError, match=":2: .*'zero' is not a number"):
            read_graph(str(bad))
        assert gc.isenabled() == enabled
        write_graph(read_graph(str(good)).graph, str(tmp_path / "written.g2o"))
        assert gc.isenabled() == enabled
    finally:
        gc.enable()


def test_a_graph_file_whose_suffix_tells_no_format_is_refused_unless_it_is_given(tmp_path):
    """``write_graph("x.xyz")`` wrote g2o silently; the suffix tells the format or the caller
    gives it, and a refusal writes nothing."""
    graph = random_graph(SE2, 4, 1, seed=44)
    unknown = tmp_path / "poses.xyz"
    with pytest.raises(ValueError, match=r"poses.xyz: its suffix tells no graph format"):
        write_graph(graph, str(unknown))
    assert not unknown.exists()
    write_graph(graph, str(unknown), "toro")
    assert unknown.read_text().startswith("VERTEX2")
    for name, first in (("out.G2O", "VERTEX_SE2"), ("out.toro", "VERTEX2")):
        write_graph(graph, str(tmp_path / name))
        assert (tmp_path / name).read_text().startswith(first)
