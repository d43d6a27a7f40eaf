"""A robust run's decisions survive its output file: rejected edges and priors are written
commented out behind a tag (g2o and gtsam leave them out), read back as rejected, left out of
the next solve, kept marked by ``optimize`` and ``convert``, and drawn apart by ``plot``."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.outliers import add_false_loops

from posegraph import plotting
from posegraph.io import read_graph, write_graph
from posegraph.io.parsing import REJECTED_PREFIX
from posegraph.problem.factors import chi2

from ..conftest import city_with_fixes
from .helpers import run, run_json


@pytest.fixture(scope="module")
def robust_output(tmp_path_factory):
    """(the robust run's -o, the corrupted input, the false loops, the false fixes)."""
    folder = tmp_path_factory.mktemp("robust")
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    source, out = folder / "false_loops.g2o", folder / "robust.g2o"
    write_graph(corrupted, str(source))
    text = run("optimize", source, "--robust", "gnc", "--robust-priors", "-o", out).stdout
    marked = int(false_loops.sum() + false_fixes.sum())
    assert f"wrote           {out} ({marked} marked rejected)" in text
    return out, corrupted, false_loops, false_fixes


def test_rejected_lines_are_commented_out_and_read_back_as_rejected(robust_output):
    out, corrupted, false_loops, false_fixes = robust_output
    lines = out.read_text().splitlines()
    marked = [line for line in lines if line.startswith(REJECTED_PREFIX)]
    assert len(marked) == false_loops.sum() + false_fixes.sum()
    read = read_graph(str(out))
    assert read.graph.num_edges == corrupted.num_edges  # all of them, the rejected marked
    edges, priors = read.rejected
    np.testing.assert_array_equal(edges, false_loops)
    np.testing.assert_array_equal(priors, false_fixes)


def test_the_file_alone_reproduces_the_robust_solution(robust_output, tmp_path):
    """Optimised again, the output's least-squares error over the measurements it keeps is the
    robust run's (1e-9 relative; the values agree to the solver's tolerance), and it is written
    with the same marks; --readmit-rejected takes the rejected back in."""
    out, corrupted, false_loops, false_fixes = robust_output
    again = tmp_path / "again.g2o"
    document = run_json("optimize", out, "-o", again)
    assert document["edges"] == corrupted.num_edges - false_loops.sum()
    first, second = read_graph(str(out)), read_graph(str(again))
    edges, priors = first.rejected
    inliers = first.graph.with_edges(~edges)
    inliers.remove_priors(priors)
    robust = chi2(first.graph.values, inliers.edges, inliers.priors)
    assert chi2(second.graph.values, inliers.edges, inliers.priors) == pytest.approx(
        robust, rel=1e-9
    )
    assert document["summary"]["final_error"] == pytest.approx(robust / 2, rel=1e-9)
    np.testing.assert_allclose(
        second.graph.values.as_matrix(), first.graph.values.as_matrix(), atol=1e-4
    )
    np.testing.assert_array_equal(second.rejected[0], false_loops)
    np.testing.assert_array_equal(second.rejected[1], false_fixes)
    readmitted = run_json("optimize", out, "--readmit-rejected")
    assert readmitted["edges"] == corrupted.num_edges
    assert readmitted["summary"]["final_error"] > document["summary"]["final_error"]


def test_convert_keeps_the_marks_and_gtsam_reads_without_them(robust_output, tmp_path):
    out, corrupted, false_loops, _ = robust_output
    toro_free = tmp_path / "copy.g2o"
    run("convert", out, toro_free)
    np.testing.assert_array_equal(read_graph(str(toro_free)).rejected[0], false_loops)
    gtsam = pytest.importorskip("gtsam")
    factors, _ = gtsam.readG2o(str(out), False)
    between = sum(1 for k in range(factors.size()) if "Between" in type(factors.at(k)).__name__)
    assert between == corrupted.num_edges - false_loops.sum()


def test_plot_draws_a_files_rejections_apart(robust_output, monkeypatch):
    out, _, false_loops, _ = robust_output
    figures = []
    monkeypatch.setattr(plotting, "save_figure", lambda figure, path: figures.append(figure))
    plotting.plot_graphs([("robust", read_graph(str(out)))], "x.png")
    labels = [text.get_text() for text in figures[0].axes[0].get_legend().get_texts()]
    assert f"{false_loops.sum()} rejected edges" in labels
