"""``posegraph info``, ``convert``, ``plot``, ``eval``, ``scale-drift`` and ``bench``, driven as a
subprocess the way a new user runs them."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world
from posegraph_datasets.monocular import monocular_sequence, write_sequence
from posegraph_datasets.outliers import add_false_loops
from posegraph_datasets.paths import BENCHMARK_GRAPHS

from posegraph.graph import EdgeSet
from posegraph.io import read_graph, write_graph
from posegraph.robust.spec import robust_mask
from tests.cli.helpers import (
    EXAMPLE,
    EXAMPLE_2D,
    assert_not_blank,
    monocular_file,
    run,
    run_json,
)

from ..conftest import city_with_fixes


def test_info_reports_problems_with_suggestions(tmp_path):
    document = run_json("info", EXAMPLE_2D)
    assert document["nodes"] == 400 and document["components"] == [400]
    assert document["problems"] == []
    ends = np.array(
        [line.split()[1:3] for line in open(EXAMPLE_2D) if line.startswith("EDGE_SE2")], dtype=int
    )
    loop_closures = int((np.abs(ends[:, 1] - ends[:, 0]) != 1).sum())  # ids are 0 … 399, in order
    assert document["loop_closures"] == loop_closures > 0
    assert f"({loop_closures} loop closures between" in run("info", EXAMPLE_2D).stdout
    broken = tmp_path / "two_parts.g2o"
    lines = [
        line
        for line in open(EXAMPLE_2D).read().splitlines()
        if not line.startswith("EDGE_SE2 199 200 ")
    ]
    broken.write_text("\n".join(lines) + "\nEDGE_SE2 5 5 1 0 0 1 0 0 1 0 1\n")
    document = run_json("info", broken, "--lenient")
    problems = " | ".join(p["what"] for p in document["problems"])
    assert "odometry chain breaks" in problems
    last = len(lines) + 1
    assert (
        f"1 line(s) skipped (first at line {last}): EDGE_SE2: edge from node 5 to itself"
        in problems
    )
    text = run("info", broken, "--lenient").stdout
    assert "→" in text  # every problem comes with a suggestion


def test_every_command_reports_the_lines_that_lenient_reading_skipped(tmp_path):
    """--lenient leaves lines out of every result: text mode says so on stderr (after the
    progress of the solve), JSON lists them by file and reason (``skipped_lines``), and --quiet
    prints nothing."""
    lines = open(EXAMPLE_2D).read().splitlines()
    landmarks = [f"LANDMARK2 {k} {k} 1.5 2.5" for k in (3, 4, 5)]  # gtsam's, not a pose tag
    broken = tmp_path / "with_landmarks.g2o"
    broken.write_text("\n".join([*lines, *landmarks, "EDGE_SE2 5 5 1 0 0 1 0 0 1 0 1"]) + "\n")
    landmark_line, self_loop_line = len(lines) + 1, len(lines) + 4
    expected = [
        {
            "path": str(broken),
            "reason": "landmark tag 'LANDMARK2': posegraph optimises poses only",
            "count": 3,
            "first_line": landmark_line,
        },
        {
            "path": str(broken),
            "reason": "EDGE_SE2: edge from node 5 to itself",
            "count": 1,
            "first_line": self_loop_line,
        },
    ]
    warning = (
        f"posegraph: warning: {broken}: 4 line(s) skipped: 3 × landmark tag 'LANDMARK2': posegraph"
        f" optimises poses only (first at line {landmark_line}); 1 × EDGE_SE2: edge from node 5 to"
        " itself (first at line "
        f"{self_loop_line}); the results leave out what those lines say\n"
    )
    output = tmp_path / "out.g2o"

    text = run("optimize", broken, "-o", output, "--lenient")
    assert text.stderr.startswith("iterating ") and text.stderr.endswith("\n" + warning)
    assert text.stderr.count("\n") == 2 and "wrote" in text.stdout
    quiet = run("optimize", broken, "-o", output, "--lenient", "--quiet", "--overwrite")
    assert quiet.stderr == quiet.stdout == ""
    assert run("convert", broken, tmp_path / "poses.tum", "--lenient").stderr == warning
    assert run("info", broken, "--lenient").stderr == ""  # its report lists them as a problem

    documents = {
        "optimize": run_json("optimize", broken, "--lenient"),
        "info": run_json("info", broken, "--lenient"),
        "convert": run_json("convert", broken, tmp_path / "poses.g2o", "--lenient"),
        "plot": run_json("plot", broken, EXAMPLE_2D, "-o", tmp_path / "both.png", "--lenient"),
        "eval": run_json("eval", broken, EXAMPLE_2D, "--lenient"),
    }
    for command, document in documents.items():
        assert document["skipped_lines"] == expected, command
    assert run_json("convert", EXAMPLE_2D, tmp_path / "clean.g2o")["skipped_lines"] == []


def test_info_counts_singular_information_and_flags_it_only_on_edges(tmp_path):
    """GNSS fixes without rotation information are singular by design: counted, not flagged
    (they were "condition number above 1e12"); a between edge that measures no rotation is
    flagged with what to check."""
    path = tmp_path / "gnss.g2o"
    odometry = "".join(f"EDGE_SE2 {k} {k + 1} 1 0 0.05 100 0 0 100 0 1000\n" for k in range(20))
    fixes = "".join(f"EDGE_PRIOR_SE2 {k} {k} 3 0 1 0 0 1 0 0\n" for k in (0, 10, 20))
    path.write_text(odometry + fixes)
    document = run_json("info", path)
    assert document["singular_information"] == 3
    assert document["condition_numbers"] == {"min": 10.0, "median": 10.0, "max": 10.0}
    assert document["problems"][0]["what"] == "21 node(s) have no vertex line"
    assert len(document["problems"]) == 1
    text = run("info", path).stdout
    assert "3 singular (directions not measured); the others SPD, condition number min 10" in text
    path.write_text(odometry + fixes + "EDGE_SE2 0 20 19 3 0 1 0 0 1 0 0\n")
    problems = [p["what"] for p in run_json("info", path)["problems"]]
    assert "1 edge(s) have singular information: directions they do not measure" in problems


def test_convert_between_formats(tmp_path):
    toro, back = tmp_path / "g.graph", tmp_path / "back.g2o"
    assert run_json("convert", EXAMPLE_2D, toro)["format"] == "toro"
    run("convert", toro, back)
    original, returned = read_graph(EXAMPLE_2D).graph, read_graph(str(back)).graph
    np.testing.assert_allclose(returned.values.as_matrix(), original.values.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(returned.edges.information, original.edges.information)
    run("convert", EXAMPLE, tmp_path / "p.tum")
    tum = np.loadtxt(tmp_path / "p.tum")
    assert tum.shape == (160, 8) and np.allclose(np.linalg.norm(tum[:, 4:], axis=1), 1)
    run("convert", EXAMPLE, tmp_path / "p.txt", "--to", "kitti")
    kitti = np.loadtxt(tmp_path / "p.txt").reshape(-1, 3, 4)
    assert np.allclose(kitti[:, :, :3] @ np.swapaxes(kitti[:, :, :3], 1, 2), np.eye(3), atol=1e-9)
    unknown = run("convert", EXAMPLE, tmp_path / "p.xyz", check_exit=2)
    assert "--to" in unknown.stderr
    source, _, _ = monocular_file(tmp_path)  # SE3 odometry and Sim3 loops: a Sim3 graph
    refused = run("convert", source, tmp_path / "m.graph", check_exit=2)
    assert (
        f"posegraph: error: {source}: TORO has no Sim3 lines; write g2o instead" in refused.stderr
    )


def test_an_output_that_cannot_hold_the_graph_is_refused_before_any_work(
    tmp_path, monkeypatch, capsys
):
    """A Sim3 graph with priors has no g2o lines (nor a graph with priors or FIX lines TORO
    ones): optimize and scale-drift say so, naming the input, before optimising, not after;
    its trajectory can be written."""
    from posegraph_cli import main

    from posegraph import Smoother

    source, _, _ = monocular_file(tmp_path)
    lines = open(source).read().splitlines()
    information = " ".join("1" if r == c else "0" for r in range(6) for c in range(r, 6))
    prior = f"EDGE_SE3_PRIOR 0 0 0 0 0 0 0 0 1 {information}"
    with_prior = tmp_path / "mono_prior.g2o"
    with_prior.write_text("\n".join(["PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1", *lines, prior]) + "\n")
    fixed = tmp_path / "fixed.g2o"
    fixed.write_text(open(EXAMPLE_2D).read() + "FIX 3\n")

    def no_work(*args, **kwargs):
        raise AssertionError("optimised a graph whose result could not be written")

    optimize = Smoother.optimize
    monkeypatch.setattr(Smoother, "optimize", no_work)
    refusals = [
        ("optimize", with_prior, "out.g2o", "g2o has no Sim3 prior line"),
        ("scale-drift", with_prior, "out.g2o", "g2o has no Sim3 prior line"),
        ("optimize", fixed, "out.graph", "TORO has no prior or FIX lines"),
    ]
    for command, path, output, reason in refusals:
        assert main.main([command, str(path), "-o", str(tmp_path / output)]) == 2
        refused = capsys.readouterr()
        assert refused.out == "" and refused.err.count("\n") == 1, refused
        assert refused.err.startswith(f"posegraph: error: {path}: {reason}"), refused.err
        assert not (tmp_path / output).exists()
    monkeypatch.setattr(Smoother, "optimize", optimize)
    assert main.main(["optimize", str(with_prior), "-o", str(tmp_path / "poses.tum")]) == 0
    assert np.loadtxt(tmp_path / "poses.tum").shape == (300, 8)


def test_plot_overlays_graphs(tmp_path):
    optimised, figure = tmp_path / "opt.g2o", tmp_path / "overlay.png"
    run("optimize", EXAMPLE_2D, "-o", optimised)
    run_json("plot", EXAMPLE_2D, optimised, "-o", figure)
    assert_not_blank(figure)
    run("plot", EXAMPLE, "-o", tmp_path / "top.png", "--view", "top")
    assert_not_blank(tmp_path / "top.png")


def test_plots_mark_priors_once_per_distinct_set(tmp_path, monkeypatch):
    """GNSS fixes are drawn as crosses at their measured positions; an optimised copy that
    shares them does not draw them again."""
    from matplotlib.collections import PathCollection

    from posegraph import plotting

    before = read_graph(EXAMPLE_2D).graph
    fixes = before.values[[0, 100, 200]]
    information = np.diag([1.0, 1.0, 0.0])
    before.add_priors(before.node_ids[[0, 100, 200]], fixes, information)
    after, other = before.copy(), before.copy()
    other.add_prior(before.node_ids[300], before.values[300], information)
    figures = []
    monkeypatch.setattr(plotting, "save_figure", lambda figure, path: figures.append(figure))
    plotting.plot_graphs([("initial", before), ("optimised", after), ("other", other)], "x.png")
    axes = figures[0].axes[0]
    labels = [text.get_text() for text in axes.get_legend().get_texts()]
    assert labels.count("3 priors") == 1 and labels.count("4 priors") == 1
    crosses = [c.get_offsets() for c in axes.collections if isinstance(c, PathCollection)]
    np.testing.assert_array_equal(crosses[0], fixes.translation)
    assert len(crosses) == 2 and len(crosses[1]) == 4


def test_plots_draw_what_a_robust_run_rejected_apart(monkeypatch):
    """In a smoother's graph that GNC left, the rejected loops are dashed red segments between
    the poses they join, the rejected fixes red circles at their measured positions, and the
    graph's label counts the rejected loops; the graph before the run draws every loop alike."""
    from posegraph import Smoother, plotting

    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    before = corrupted.copy()
    smoother = Smoother(corrupted)
    smoother.optimize(robust="gnc", robust_priors=True)
    figures = []
    monkeypatch.setattr(plotting, "save_figure", lambda figure, path: figures.append(figure))
    plotting.plot_graphs([("initial", before), ("optimised", smoother)], "x.png")
    axes = figures[0].axes[0]
    labels = [text.get_text() for text in axes.get_legend().get_texts()]
    loops = int(robust_mask(corrupted, "loops").sum())
    rejected_loops, rejected_fixes = int(false_loops.sum()), int(false_fixes.sum())
    assert labels == [
        f"initial ({loops} loop closures)",
        f"{len(false_fixes)} priors",
        f"optimised ({loops} loop closures, {rejected_loops} rejected)",
        f"{rejected_loops} rejected edges",
        f"{rejected_fixes} rejected priors",
    ]
    segments = [len(c.get_segments()) for c in axes.collections if hasattr(c, "get_segments")]
    assert segments == [loops, loops - rejected_loops, rejected_loops]
    (dashed,) = [c for c in axes.collections if c.get_label() == labels[3]]
    positions, edges = corrupted.positions(), corrupted.edges
    ends = np.stack([positions[edges.i[false_loops]], positions[edges.j[false_loops]]], axis=1)
    np.testing.assert_allclose(np.array(dashed.get_segments()), ends)
    (circles,) = [c for c in axes.collections if c.get_label() == labels[4]]
    fixes = corrupted.priors.measurements[false_fixes].translation
    np.testing.assert_allclose(circles.get_offsets(), fixes)


def test_eval_reports_ate_and_rpe(tmp_path):
    from posegraph_datasets.generators import sphere

    from posegraph.io.trajectories import Trajectory, write_trajectory

    graph, truth = sphere(rings=8, poses_per_ring=20, seed=2)  # the bundled example's truth
    truth_path = tmp_path / "truth.tum"
    write_trajectory(Trajectory(np.arange(160.0), truth), str(truth_path), "tum")
    optimised = tmp_path / "opt.g2o"
    run("optimize", EXAMPLE, "-o", optimised)
    before = run_json("eval", EXAMPLE, truth_path)
    after = run_json("eval", optimised, truth_path, "--plot", tmp_path / "ate.png")
    assert after["ate"]["rmse"] < before["ate"]["rmse"]
    assert after["matched_poses"] == after["estimate_poses"] == 160
    assert_not_blank(tmp_path / "ate.png")
    sim3 = run_json("eval", optimised, truth_path, "--align", "sim3")
    assert sim3["ate"]["rmse"] <= after["ate"]["rmse"] + 1e-12
    text = run("eval", optimised, truth_path).stdout
    assert "ATE" in text and "RPE" in text
    assert after["planar_ate_floor"] is None and "floor" not in text
    too_far = run("eval", optimised, truth_path, "--delta", 160, check_exit=2)
    assert (
        f"posegraph: error: {optimised} against {truth_path}: the RPE step is 1 to 159 poses (of"
        " the 160 matched), not 160" in too_far.stderr
    )
    truncated = tmp_path / "truncated.tum"
    truncated.write_text("".join(open(truth_path).readlines()[:2]))
    unpaired = run("eval", optimised, truncated, check_exit=2)
    assert unpaired.stderr.startswith(
        f"posegraph: error: {optimised} against {truncated}: only 2 poses pair"
    ), unpaired.stderr


def test_eval_of_a_2d_estimate_against_3d_ground_truth_gives_the_planar_floor(tmp_path):
    """A 2D graph is lifted to z = 0; ground truth that leaves its plane (here by ±5 cm)
    puts a floor under the ATE, which eval reports."""
    from posegraph.io import read_graph
    from posegraph.io.trajectories import Trajectory, write_trajectory

    graph = read_graph(EXAMPLE_2D).graph
    lifted = Trajectory.of_graph(graph)
    bumps = 0.05 * (-1.0) ** np.arange(graph.num_nodes)
    truth = type(lifted.poses)(lifted.poses.rotation, lifted.positions + bumps[:, None] * [0, 0, 1])
    truth_path = tmp_path / "truth3d.tum"
    write_trajectory(Trajectory(lifted.keys, truth), str(truth_path), "tum")
    document = run_json("eval", EXAMPLE_2D, truth_path)
    assert 0.04 < document["planar_ate_floor"] <= document["ate"]["rmse"]
    text = run("eval", EXAMPLE_2D, truth_path).stdout
    assert (
        f"ATE floor        rmse {document['planar_ate_floor']:.6g}  (the estimate is planar" in text
    )


@pytest.mark.parametrize("name", BENCHMARK_GRAPHS)
def test_every_command_succeeds_on_the_benchmark_graphs(tmp_path, shared_dataset, name):
    source = shared_dataset(name)
    run("info", source)
    run("convert", source, tmp_path / "g.graph")
    run("plot", source, "-o", tmp_path / "g.png")
    assert_not_blank(tmp_path / "g.png")
    document = run_json("optimize", source, "-o", tmp_path / "opt.g2o")
    assert document["summary"]["final_error"] <= document["summary"]["initial_error"]


def test_eval_gives_the_drift_over_path_segments(tmp_path):
    """Over 20 and 40 m, the bundled sphere (160 poses on 10 m rings) gets the drift, pooled
    and per length, as ``segment_drift`` gives it; no segment of 10 km fits, which the report
    says; and a length that is not positive is refused."""
    from posegraph_datasets.generators import sphere

    from posegraph.io.trajectories import Trajectory, write_trajectory
    from posegraph.trajectory.evaluation import segment_drift

    _, truth = sphere(rings=8, poses_per_ring=20, seed=2)
    truth_path = tmp_path / "truth.tum"
    write_trajectory(Trajectory(np.arange(160.0), truth), str(truth_path), "tum")
    too_long = ("--segment-lengths", "10000")
    assert run_json("eval", EXAMPLE, truth_path, *too_long)["drift"] is None
    text = run("eval", EXAMPLE, truth_path, *too_long).stdout
    assert "drift            no segment fits: the ground truth's path is shorter than 10000" in text
    document = run_json("eval", EXAMPLE, truth_path, "--segment-lengths", "20", "40")
    assert document["segment_lengths"] == [20.0, 40.0]
    assert [d["lengths"] for d in document["drift_by_length"]] == [[20.0], [40.0]]
    estimate = read_graph(EXAMPLE).graph
    aligned = Trajectory.of_graph(estimate)  # se3-aligned drift equals unaligned drift
    expected = segment_drift(truth, aligned.poses, (20.0, 40.0))
    for got, want in zip(document["drift_by_length"], expected, strict=True):
        assert got["segments"] == want.segments
        assert got["translation_percent"] == pytest.approx(want.translation_percent, rel=1e-9)
    text = run("eval", EXAMPLE, truth_path, "--segment-lengths", "20", "40").stdout
    assert f"over {document['drift']['segments']} segments of 20–40 (KITTI's metric)" in text
    refused = run("eval", EXAMPLE, truth_path, "--segment-lengths", "0", check_exit=2)
    assert "segment lengths must be positive, not [0.0]" in refused.stderr


@pytest.mark.parametrize("solver", ["lm", "dogleg"])
def test_bench_times_posegraph_against_gtsam(shared_dataset, solver):
    """`posegraph bench` gives a row per graph: both errors, and the time ratio."""
    shared_dataset("tinyGrid3D.g2o")  # skips without ../shared
    arguments = ("--graphs", "tinyGrid3D", "--solver", solver, "--repeats", "1", "--budget", "0")
    table = run_json("bench", *arguments)["table"]
    (row,) = [line for line in table.splitlines() if line.startswith("| tinyGrid3D.g2o")]
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert float(cells[4]) == pytest.approx(9.3139, rel=1e-4)  # gtsam's error
    assert float(cells[7]) == pytest.approx(9.3139, rel=1e-4)  # posegraph's
    assert float(cells[9]) > 0.0  # the time ratio


def test_scale_drift_command(tmp_path):
    source, truth, _ = monocular_file(tmp_path)
    out, figure = tmp_path / "corrected.tum", tmp_path / "drift.png"
    document = run_json("scale-drift", source, "-o", out, "--gt", truth, "--plot", figure)
    assert document["ate_after"] * 10 <= document["ate_before"]
    assert document["scale_range"][0] < 0.5 < document["scale_range"][1] == pytest.approx(1.0)
    assert_not_blank(figure)
    corrected = np.loadtxt(out)
    assert corrected.shape == (300, 8)
    evaluated = run_json("eval", out, truth)
    assert evaluated["ate"]["rmse"] == pytest.approx(document["ate_after"], rel=1e-9)
    camera_from_world = tmp_path / "cw.tum"
    run("scale-drift", source, "-o", camera_from_world, "--convention", "camera_from_world")
    assert not np.allclose(np.loadtxt(camera_from_world)[:, 1:4], corrected[:, 1:4])
    # The optimised Sim3 graph is written in the input's dialect, as optimize writes it.
    for dialect in ("a", "b"):
        write_sequence(monocular_sequence(drift=0.01, seed=1), source, truth, dialect=dialect)
        graph_out = tmp_path / f"corrected_{dialect}.g2o"
        run("scale-drift", source, "-o", graph_out)
        assert read_graph(str(graph_out)).sim3_dialect == dialect


def test_scale_drift_command_rejects_false_loops(tmp_path):
    """--robust gnc rejects exactly the false Sim3 loops of a sequence where least squares bends
    to them, and ends where the correction without them does; the report names what the kernel
    covered and rejected. (Seed 1 at 1% drift: stop 29's scale-drift table.)"""
    clean, truth, _ = monocular_file(tmp_path)
    source, _, false = monocular_file(tmp_path, false_loops=0.3)
    assert false.size == 9
    without = run_json("scale-drift", clean, "--gt", truth)
    # Least squares bends to the false loops and may crawl there: whether it converges is moot.
    plain = run_json("scale-drift", source, "--gt", truth, check_exit=None)
    robust = run_json("scale-drift", source, "--gt", truth, "--robust", "gnc")
    assert plain["ate_after"] > 10 * without["ate_after"]
    assert robust["summary"]["rejected_edges"] == false.tolist()
    assert robust["summary"]["edges_under_kernel"] == 29  # 20 true loops and the false ones
    assert robust["ate_after"] == pytest.approx(without["ate_after"], rel=1e-3)
    text = run("scale-drift", source, "--robust", "gnc").stdout
    assert "robust          gnc:" in text and "on 29 of 328 edges: 9 edge(s) rejected: " in text
    inliers = tmp_path / "inliers.g2o"
    run("scale-drift", source, "--robust", "gnc", "-o", inliers, "--drop-rejected")
    kept = np.setdiff1d(np.arange(328), false)
    written, read = read_graph(str(inliers)).graph, read_graph(str(source)).graph
    np.testing.assert_array_equal(written.edges.i, read.edges.i[kept])
    np.testing.assert_array_equal(written.edges.j, read.edges.j[kept])


def test_scale_drift_warns_that_a_file_of_se3_edges_only_carries_no_scale_change(tmp_path):
    """A file of SE3 edges only gets a warning; an SE2 file is refused, naming it."""
    warning = "no Sim3 edge: each loop closure only says that its ends share one scale"
    se3_only = run("scale-drift", EXAMPLE)
    assert f"posegraph: warning: {EXAMPLE}: {warning}" in se3_only.stderr
    assert warning not in run("scale-drift", EXAMPLE, "--json").stderr
    source, truth = tmp_path / "mono.g2o", tmp_path / "gt.tum"
    write_sequence(monocular_sequence(drift=0.01, seed=1), str(source), str(truth))
    assert "warning" not in run("scale-drift", source).stderr
    planar = run("scale-drift", EXAMPLE_2D, check_exit=2)
    assert (
        f"{EXAMPLE_2D}: scale-drift correction needs an SE3 or Sim3 graph, not SE2" in planar.stderr
    )


def test_reports_give_the_scale_information_of_lifted_se3_odometry(tmp_path):
    """The SE3 odometry of a file with Sim3 loops is lifted to Sim3 with some log-scale
    information: info and scale-drift report it, with the scale change it allows. At 2% drift
    per keyframe the default allows the drift the loops measured, and GNC keeps all 20 loops.
    A stiffer lift makes GNC reject them all: the odometry's own rule, which allows 0.17% and
    was the default before the loops were heard (stop 29's scale-drift table). The report then
    says it may be too stiff, and setting it as the hint says keeps every loop again."""
    from posegraph.sim3.lifting import default_scale_information

    source, truth = tmp_path / "mono.g2o", tmp_path / "gt.tum"
    sequence = monocular_sequence(drift=0.02, seed=1)
    write_sequence(sequence, str(source), str(truth))
    default = sequence.sim3_graph().edges.information[0, 6, 6]
    assert run_json("info", source)["lifted_scale_information"] == pytest.approx(default, rel=1e-9)
    assert run_json("info", source, "--scale-information", 2500)["lifted_scale_information"] == 2500
    assert run_json("info", EXAMPLE)["lifted_scale_information"] is None  # SE3 lines only
    optimized = run_json("optimize", source, "--scale-information", 2500)
    assert optimized["lifted_scale_information"] == 2500
    # A file of SE3 lines only is lifted by the correction, not the reader; it said nothing.
    edges = read_graph(EXAMPLE).graph.edges
    weights = np.trace(edges.information[:, :3, :3], axis1=1, axis2=2) / 3
    own = np.median(weights * (edges.measurements.translation**2).sum(axis=1))
    corrected = run_json("scale-drift", EXAMPLE)
    assert corrected["lifted_scale_information"] == pytest.approx(own, rel=1e-12)
    assert (
        run_json("scale-drift", EXAMPLE, "--scale-information", 50)["lifted_scale_information"]
        == 50
    )
    assert (
        "lifted          SE3 lines to Sim3: log-scale information"
        in run("scale-drift", EXAMPLE).stdout
    )
    sigma = f"{100 / np.sqrt(default):.2g}%"
    assert f"a scale change of {sigma} per edge" in run("info", source).stdout
    kept = run_json("scale-drift", source, "--gt", truth, "--robust", "gnc")
    assert kept["summary"]["rejected_edges"] == []
    assert "allows a scale change" not in run("scale-drift", source, "--robust", "gnc").stdout

    odometry = sequence.odometry.edges
    rule = default_scale_information(odometry.information, odometry.measurements)
    stiffly = ["--robust", "gnc", "--scale-information", rule]
    text = run("scale-drift", source, *stiffly).stdout
    assert "most of the edges under the kernel were rejected" in text
    assert f"allows a scale change of only {100 / np.sqrt(rule):.2g}% per edge" in text
    stiff = run_json("scale-drift", source, "--gt", truth, *stiffly)
    assert len(stiff["summary"]["rejected_edges"]) == 20
    two_percent = 1 / 0.02**2  # as the hint says, for the drift of this sequence
    suggested = run_json(
        "scale-drift", source, "--gt", truth, "--robust", "gnc", "--scale-information", two_percent
    )
    assert suggested["lifted_scale_information"] == two_percent
    assert suggested["summary"]["rejected_edges"] == []
    assert max(suggested["ate_after"], kept["ate_after"]) * 100 < stiff["ate_after"]


def test_info_reads_leniently_and_names_the_repair(tmp_path):
    """``info`` never refuses a file it can parse: indefinite information is listed as a problem
    with its count, first line and the option; ``optimize`` then reads it with that option, and
    the reports say how the information was read."""
    source = tmp_path / "indefinite.g2o"
    lines = open(EXAMPLE).read().splitlines()
    edges = [k for k, line in enumerate(lines) if line.startswith("EDGE_SE3:QUAT")]
    for k in edges[5:8]:
        fields = lines[k].split()
        fields[9 + 11 : 9 + 13] = ["84022", "132748"]  # the (z, qx), (z, qy) entries
        lines[k] = " ".join(fields)
    source.write_text("\n".join(lines) + "\n")
    run("optimize", source, check_exit=2)
    document = run_json("info", source)
    assert document["skipped_lines"][0]["count"] == 3
    [problem] = [p for p in document["problems"] if "semi-definite" in p["what"]]
    assert problem["what"].startswith(f"3 line(s) skipped (first at line {edges[5] + 1})")
    assert "--repair-information psd" in problem["what"]
    assert document["rotation_information"] == "phi" and document["repaired_information"] == 0
    repaired = run_json("optimize", source, "--repair-information", "psd")
    assert repaired["repaired_information"] == 3 and repaired["edges"] == len(edges)
    text = run("optimize", source, "--repair-information", "isotropic").stdout
    assert f"information     {len(edges)} matrices repaired" in text
    assert "rotation info   over φ, as gtsam reads it" in text
    g2o = run_json("optimize", source, "--repair-information", "psd", "--g2o-rotation-information")
    assert g2o["rotation_information"] == "quaternion"


def test_info_names_false_loops_and_misstated_information(tmp_path):
    """``info`` solves in least squares and tests the noise: false loops, and information
    scaled 1e4× from the noise, are named with the option, in text and --json."""
    graph, _ = manhattan_world(400, seed=5)
    corrupted, _ = add_false_loops(graph, 0.1, seed=1)
    scaled = graph.copy()
    edges = scaled.edges
    scaled.edges = EdgeSet(edges.i, edges.j, edges.measurements, edges.information * 1e4)
    for name, noisy, words, option in [
        ("false_loops.g2o", corrupted, "likely false loops", "--robust gnc"),
        ("scaled.g2o", scaled, "understates their noise about", "--robust gnc"),
    ]:
        path = tmp_path / name
        write_graph(noisy, str(path))
        document = run_json("info", path)
        problems = [p for p in document["problems"] if words in p["what"]]
        assert problems and option in problems[0]["suggestion"], document["problems"]
        assert {c["kind"] for c in document["noise"]} == {"odometry", "loop closures"}
        text = run("info", path).stdout
        assert words in text and "noise           χ² per dof" in text
