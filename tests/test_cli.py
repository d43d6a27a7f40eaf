"""The ``posegraph`` command, driven as a subprocess the way a new user runs it."""

from __future__ import annotations

import json
import os
import pty
import re
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest
from posegraph_cli.schema import SCHEMAS
from posegraph_datasets import example
from posegraph_datasets.monocular import monocular_sequence, write_sequence
from posegraph_datasets.outliers import add_false_loops
from posegraph_datasets.paths import BENCHMARK_GRAPHS

from posegraph.api import robust_mask
from posegraph.factors import chi2
from posegraph.io import read_graph, write_graph
from posegraph.lie import SE3

from .conftest import city_with_fixes, maps_joined_by_positions, sim3_scale_chain
from .malformed import MALFORMED
from .test_malformed import write_case

jsonschema = pytest.importorskip("jsonschema")

COMMAND = (
    [shutil.which("posegraph")]
    if shutil.which("posegraph")
    else [sys.executable, "-m", "posegraph_cli.main"]
)
EXAMPLE = str(example("sphere_small.g2o"))
EXAMPLE_2D = str(example("manhattan_small.g2o"))


def run(*args, check_exit: int | None = 0, timeout: float = 300):
    completed = subprocess.run(
        [*COMMAND, *map(str, args)], capture_output=True, text=True, timeout=timeout
    )
    if check_exit is not None:
        assert completed.returncode == check_exit, completed.stderr + completed.stdout
    return completed


def _not_json(constant: str):
    raise ValueError(f"{constant} is not JSON")


def run_json(command: str, *args, check_exit: int | None = 0):
    completed = run(command, *args, "--json", check_exit=check_exit)
    document = json.loads(completed.stdout, parse_constant=_not_json)  # no NaN or Infinity
    jsonschema.validate(document, SCHEMAS[command])
    return document


def assert_not_blank(png) -> None:
    import matplotlib.image

    pixels = matplotlib.image.imread(str(png))[..., :3]
    assert pixels.var() > 1e-3
    assert (pixels.min(axis=2) < 0.9).mean() > 0.005  # more than 0.5% of the pixels are drawn


def test_version_and_help():
    assert run("--version").stdout.startswith("posegraph ")
    for command in ("optimize", "info", "convert", "plot", "eval", "bench"):
        text = run(command, "--help").stdout
        assert "examples:" in text and f"posegraph {command}" in text


def test_start_up_leaves_plotting_and_statistics_unloaded():
    """matplotlib and scipy.stats each add about 0.4 s to a start; only plotting needs the first."""
    probe = "import sys, posegraph_cli.main; print(' '.join(sorted(sys.modules)))"
    loaded = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout.split()
    assert "posegraph.api" in loaded
    assert not {"matplotlib", "scipy.stats"} & set(loaded)


def test_optimize_the_bundled_example(tmp_path):
    out, figure = tmp_path / "out.g2o", tmp_path / "out.png"
    document = run_json("optimize", EXAMPLE, "-o", out, "--plot", figure)
    summary = document["summary"]
    assert summary["converged"] and summary["final_error"] < summary["initial_error"]
    assert read_graph(str(out)).graph.num_nodes == document["nodes"] == 160
    assert_not_blank(figure)
    # Piped output: a readable summary on stdout and no progress lines on stderr.
    text = run("optimize", EXAMPLE)
    assert "termination" in text.stdout and "error ½Σrᵀ Ω r" in text.stdout
    assert text.stderr == ""
    assert run("optimize", EXAMPLE, "--quiet").stdout == ""


def test_covariances_of_every_pose_equal_gtsams(tmp_path):
    """``--covariances`` writes each pose's marginal covariance at the optimum, which must equal
    gtsam.Marginals at the optimised graph's values (1e-6 relative; gtsam holds the gauge node
    with a σ = 1e-6 prior); the gauge node's is zero."""
    gtsam = pytest.importorskip("gtsam")
    from posegraph.validation.gtsam_bridge import graph_to_gtsam, matrix_from_gtsam

    out, written = tmp_path / "out.g2o", tmp_path / "covariances.txt"
    document = run_json("optimize", EXAMPLE_2D, "-o", out, "--covariances", written)
    assert document["covariances"] == str(written)
    header = [line for line in written.read_text().splitlines() if line.startswith("#")]
    assert "(x, y, theta)" in header[0] and header[1].split()[1:4] == ["id", "x*x", "x*y"]
    table = np.loadtxt(written)
    graph = read_graph(str(out)).graph
    np.testing.assert_array_equal(table[:, 0], graph.node_ids)
    rows, columns = np.triu_indices(3)
    covariances = np.zeros((len(table), 3, 3))
    covariances[:, rows, columns] = covariances[:, columns, rows] = table[:, 1:]
    assert np.all(covariances[0] == 0)  # the gauge
    factors, values = graph_to_gtsam(graph)
    marginals = gtsam.Marginals(factors, values)
    for k in range(1, graph.num_nodes, 37):
        node = int(graph.node_ids[k])
        expected = matrix_from_gtsam(graph.group, marginals.marginalCovariance(node))
        np.testing.assert_allclose(
            covariances[k], expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max()
        )


def test_covariances_that_do_not_exist_are_refused_and_nothing_is_written(tmp_path):
    """A map held only by a position prior has a rotation that nothing measures."""
    graph_file, out, written = tmp_path / "free.g2o", tmp_path / "out.g2o", tmp_path / "c.txt"
    graph_file.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
        "EDGE_PRIOR_SE2 0 0 0 0 1 0 0 1 0 0\n"
    )
    completed = run("optimize", graph_file, "-o", out, "--covariances", written, check_exit=2)
    assert "information matrix is singular" in completed.stderr
    assert "Nothing written" in completed.stderr and "Traceback" not in completed.stderr
    assert not out.exists() and not written.exists()
    run("optimize", graph_file, "--covariances", graph_file, check_exit=2)  # never the input


def test_nodes_with_directions_nothing_measures_are_named(tmp_path):
    """A triangle and a leaf, node 3, seen by one position-only edge: its heading is measured
    by nothing. ``optimize`` with defaults ended in an internal error (exit 3: chordal
    relaxation's singular system); now it optimises, and ``info`` and the refusal of
    covariances name the node."""
    graph_file = tmp_path / "leaf.g2o"
    full = "100 0 0 100 0 100"
    graph_file.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 1.6\nVERTEX_SE2 2 1 1 3.1\nVERTEX_SE2 3 2 1 0.7\n"
        f"EDGE_SE2 0 1 1 0 1.57 {full}\nEDGE_SE2 1 2 1 0 1.57 {full}\n"
        f"EDGE_SE2 2 0 1.4 0.1 -2.3 {full}\nEDGE_SE2 1 3 1 -1 0 100 0 0 100 0 0\n"
    )
    named = (
        "1 node(s) have directions that no edge or prior measures (node 3: 1 of its 3 directions)"
    )
    assert named in [p["what"] for p in run_json("info", graph_file)["problems"]]
    optimized = run_json("optimize", graph_file)["summary"]
    assert optimized["initialization"] == "chordal" and optimized["converged"]
    completed = run("optimize", graph_file, "--covariances", tmp_path / "c.txt", check_exit=2)
    assert "measured by nothing (node 3: 1 of its 3 directions)" in completed.stderr


def test_a_map_that_can_turn_about_position_only_edges_is_named_and_has_no_covariances(tmp_path):
    """Two SE3 maps joined by two position-only edges: the second can turn about the line
    through them. No node has a direction of its own that nothing measures, and H factorises
    at the optimum, so covariances were written (variances of 1e11 to 5e13 for that turn).
    Now ``info`` names the nodes that turn, and ``--covariances`` is refused, with nothing
    written."""
    graph_file, out, written = tmp_path / "maps.g2o", tmp_path / "out.g2o", tmp_path / "c.txt"
    write_graph(maps_joined_by_positions(SE3, 2), str(graph_file))
    named = "nodes 1010, 1012, 1014, … (20 nodes) move together without changing any residual"
    assert any(p["what"].startswith(named) for p in run_json("info", graph_file)["problems"])
    completed = run("optimize", graph_file, "-o", out, "--covariances", written, check_exit=2)
    assert f"measured by nothing ({named}" in completed.stderr
    assert "Traceback" not in completed.stderr
    assert not out.exists() and not written.exists()


def monocular_file(tmp_path, false_loops: float = 0.0) -> tuple[str, str, np.ndarray]:
    """A generated monocular sequence (1% scale drift, seed 1) as a g2o file, with that share of
    false Sim3 loop closures; (its path, its ground truth's path, the false edges' indices)."""
    source, truth = tmp_path / "mono.g2o", tmp_path / "gt.tum"
    sequence = monocular_sequence(drift=0.01, seed=1)
    write_sequence(sequence, str(source), str(truth))
    if not false_loops:
        return str(source), str(truth), np.zeros(0, dtype=int)
    corrupted, false = add_false_loops(sequence.sim3_graph(), false_loops, seed=1)
    source = tmp_path / "mono_false_loops.g2o"
    write_graph(corrupted, str(source))
    return str(source), str(truth), np.flatnonzero(false)


@pytest.mark.parametrize(
    "options",
    [[], ["--robust", "gnc"], ["--solver", "dogleg"]],
    ids=["least squares", "gnc", "dogleg"],
)
@pytest.mark.parametrize("command", ["optimize", "scale-drift"])
def test_progress_is_shown_on_a_terminal(tmp_path, command, options):
    """Under a pseudo-terminal, optimize and scale-drift print an iteration table while they
    run; a GNC run's table names the stage of each iteration, and the dogleg's gives its
    trust-region radius where Levenberg-Marquardt's gives λ."""
    source = EXAMPLE if command == "optimize" else monocular_file(tmp_path)[0]
    robust = "--robust" in options
    main, secondary = pty.openpty()
    process = subprocess.Popen(
        [*COMMAND, command, source, *options],
        stdin=secondary,
        stdout=secondary,
        stderr=secondary,
    )
    os.close(secondary)
    output = b""
    while True:
        try:
            chunk = os.read(main, 4096)
        except OSError:
            break
        if not chunk:
            break
        output += chunk
    os.close(main)
    assert process.wait(timeout=120) == 0
    text = output.decode()
    assert "iter" in text and ("radius" if "dogleg" in options else "lambda") in text
    assert "    1 " in text  # the first iteration's line
    assert ("stage" in text) == robust
    assert ("s  least squares" in text) == robust  # after the time column


def test_optimize_refuses_to_overwrite_its_input(tmp_path):
    """Unless --overwrite is given; and not even then when the file is read-only (the atomic
    write's rename would replace it regardless, for root whatever its mode)."""
    source = tmp_path / "graph.g2o"
    shutil.copy(EXAMPLE, source)
    before = source.read_text()
    refused = run("optimize", source, "-o", source, check_exit=2)
    assert "refusing to overwrite" in refused.stderr and source.read_text() == before
    run("optimize", source, "-o", source, "--overwrite")
    optimised = source.read_text()
    assert optimised != before
    source.chmod(0o444)
    refused = run(
        "optimize", source, "-o", source, "--overwrite", "--init", "odometry", check_exit=2
    )
    assert (
        refused.stderr.count("\n") == 1
        and f"{source}: cannot write: the file is read-only" in refused.stderr
    )
    assert refused.stdout == "" and source.read_text() == optimised  # refused before any work


def test_outputs_are_checked_before_any_work(tmp_path):
    """A figure format matplotlib cannot write, a missing folder or an unknown suffix stops the
    command at once, in one line naming the path, before anything is optimised or written."""
    out = tmp_path / "out.g2o"
    cases = [
        (["optimize", EXAMPLE, "-o", out, "--plot", tmp_path / "fig.xyz"], "fig.xyz"),
        (["optimize", EXAMPLE, "-o", out, "--plot", tmp_path / "no" / "f.png"], "f.png"),
        (["optimize", EXAMPLE, "-o", tmp_path / "no" / "out.g2o"], "no/out.g2o"),
        (["optimize", EXAMPLE, "-o", tmp_path / "out.txt"], "out.txt"),
        (["convert", EXAMPLE, tmp_path / "out.txt"], "say --to"),
        (["scale-drift", EXAMPLE, "-o", out, "--plot", tmp_path / "d.bmp"], "d.bmp"),
        (["plot", EXAMPLE, "-o", tmp_path / "p.doc"], "p.doc"),
        (["eval", EXAMPLE, EXAMPLE, "--plot", tmp_path / "no" / "e.png"], "e.png"),
    ]
    for args, named in cases:
        failed = run(*args, check_exit=2)
        assert failed.stderr.count("\n") == 1 and named in failed.stderr, args
        assert "Traceback" not in failed.stderr and "/." not in failed.stderr  # no temporary
        assert list(tmp_path.iterdir()) == [], args


def test_optimize_options(tmp_path):
    document = run_json(
        "optimize", EXAMPLE_2D, "--solver", "gn", "--init", "odometry", "--fix", "3", "7"
    )
    assert document["summary"]["method"] == "gn"
    assert document["summary"]["initialization"] == "odometry"
    assert document["summary"]["num_variables"] == (400 - 2) * 3
    limited = run("optimize", EXAMPLE, "--max-iterations", "1", "--json", check_exit=1)
    assert json.loads(limited.stdout)["summary"]["termination"] == "maximum iterations reached"
    report = run("optimize", EXAMPLE, "--max-iterations", "1", check_exit=1).stdout
    assert "(not converged; --max-iterations raises the limit)" in report
    unknown = run("optimize", EXAMPLE, "--fix", "99999", check_exit=2)
    assert unknown.stderr.count("\n") == 1 and "node 99999" in unknown.stderr


def test_a_map_away_from_the_origin_stays_where_the_file_has_it(tmp_path):
    """Georeferenced odometry (a tree, so "auto" composes it) and a robust run on it: the first
    pose is the gauge and keeps the file's value; it was moved to the origin."""
    graph = tmp_path / "utm.g2o"
    graph.write_text(
        "VERTEX_SE2 0 500000.5 4000000.25 0.3\nVERTEX_SE2 1 500001 4000000 0.3\n"
        "EDGE_SE2 0 1 1 0 0.1 1 0 0 1 0 1\n"
    )
    for extra in ([], ["--robust", "gnc"]):
        run("optimize", graph, "-o", tmp_path / "out.g2o", "--overwrite", "--quiet", *extra)
        out = read_graph(tmp_path / "out.g2o").graph
        np.testing.assert_array_equal(
            out.values[0].as_matrix(), read_graph(graph).graph.values[0].as_matrix()
        )
        assert out.positions()[1] == pytest.approx(
            [500000.5 + np.cos(0.3), 4000000.25 + np.sin(0.3)]
        )


def test_robust_priors_reject_false_fixes_read_from_a_file(tmp_path):
    """EDGE_PRIOR_SE2 lines, 30% of them false: `--robust gnc --robust-priors` names exactly the
    false ones (by their order among the file's priors); `--robust gnc` alone rejects none."""
    graph, false = city_with_fixes(0.3, seed=0)
    path = tmp_path / "fixes.g2o"
    write_graph(graph, str(path))
    robust = run_json("optimize", path, "--robust", "gnc", "--robust-priors")["summary"]
    assert robust["rejected_priors"] == np.flatnonzero(false).tolist()
    assert robust["rejected_edges"] == []
    loops = int(robust_mask(graph, "loops").sum())
    assert (robust["edges_under_kernel"], robust["priors_under_kernel"]) == (loops, false.size)
    loops_only = run_json("optimize", path, "--robust", "gnc")["summary"]
    assert loops_only["rejected_priors"] == []
    assert (loops_only["edges_under_kernel"], loops_only["priors_under_kernel"]) == (loops, 0)
    text = run("optimize", path, "--robust", "gnc", "--robust-priors").stdout
    first = ", ".join(f"on {graph.node_ids[graph.priors.i[k]]}" for k in np.flatnonzero(false)[:5])
    covered = f"on {loops} of {graph.num_edges} edges and {false.size} priors: "
    assert f"{covered}0 edge(s) rejected; {false.sum()} prior(s) rejected: {first}, …" in text


def test_robust_report_names_the_rejected_loops_by_their_nodes(tmp_path):
    """The text report names the first rejected loops as i→j by node id, the same edges as
    the JSON's rejected_edges, and points to --json for the rest."""
    graph, _ = city_with_fixes(0.0, seed=0)
    corrupted, false = add_false_loops(graph, 0.1, seed=0)
    path = tmp_path / "false_loops.g2o"
    write_graph(corrupted, str(path))
    rejected = run_json("optimize", path, "--robust", "gnc")["summary"]["rejected_edges"]
    assert rejected == np.flatnonzero(false).tolist()
    ids, edges = corrupted.node_ids, corrupted.edges
    first = ", ".join(f"{ids[edges.i[k]]}→{ids[edges.j[k]]}" for k in rejected[:5])
    text = run("optimize", path, "--robust", "gnc").stdout
    assert f"{len(rejected)} edge(s) rejected: {first}, … (--json lists all)" in text


def test_robust_report_says_when_most_loops_were_rejected(tmp_path):
    """Where every edge's information overstates its accuracy 1000-fold, the loops all fail
    GNC's gate against the trusted odometry: the report then says that most were rejected and
    what to check. With the file's information, where only the false loops go, it does not."""
    graph, _ = city_with_fixes(0.0, seed=0)
    corrupted, _ = add_false_loops(graph, 0.1, seed=0)
    path = tmp_path / "loops.g2o"
    write_graph(corrupted, str(path))
    assert (
        "most of the edges under the kernel" not in run("optimize", path, "--robust", "gnc").stdout
    )
    loops = robust_mask(corrupted, "loops")
    corrupted.edges.information[:] *= 1e3
    write_graph(corrupted, str(path))
    text = run("optimize", path, "--robust", "gnc").stdout
    rejected = run_json("optimize", path, "--robust", "gnc")["summary"]["rejected_edges"]
    assert 2 * len(rejected) > loops.sum()
    assert "most of the edges under the kernel were rejected" in text
    assert "widen the kernel (--robust gnc:WIDTH)" in text


def test_a_closed_output_pipe_ends_quietly():
    """`posegraph info g.g2o | head -1`: no error line, no traceback, exit 1 (interrupted)."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    completed = subprocess.run(
        [*COMMAND, "info", EXAMPLE],
        stdout=write_end,
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
    )
    os.close(write_end)
    assert (completed.returncode, completed.stderr) == (1, "")


def test_edge2_order_option(tmp_path):
    """The file's values are 0.5 along x from the measurement, weighed by I11 = 4."""
    path = tmp_path / "g2o_order.graph"
    path.write_text("VERTEX2 0 0 0 0\nVERTEX2 1 1.5 0 0\nEDGE2 0 1 1 0 0 4 1 0.5 9 2 16\n")
    document = run_json("optimize", path, "--edge2-order", "g2o")
    assert document["summary"]["input_error"] == pytest.approx(0.5 * 0.5**2 * 4, rel=1e-12)


def test_ctrl_c_stops_cleanly_and_writes_the_best_values(tmp_path, shared_dataset):
    """SIGINT once a long run has taken a step (read off its progress table on a
    pseudo-terminal): exit 1, no traceback, the summary says so, and the values reached so far,
    not the file's, are written."""
    source, out = shared_dataset("torus3D.g2o"), tmp_path / "partial.g2o"
    main, secondary = pty.openpty()
    process = subprocess.Popen(
        [*COMMAND, "optimize", source, "-o", out, "--init", "file"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=secondary,
        text=True,
    )
    os.close(secondary)
    progress = b""
    while not _an_accepted_step(progress) and (chunk := _read_available(main)):
        progress += chunk
    process.send_signal(signal.SIGINT)
    stdout, _ = process.communicate(timeout=120)
    while chunk := _read_available(main):
        progress += chunk
    os.close(main)
    assert process.returncode == 1, progress.decode()
    assert "Traceback" not in progress.decode()
    assert "interrupted (Ctrl-C)" in stdout
    written, given = read_graph(str(out)).graph, read_graph(source).graph
    assert written.num_nodes == given.num_nodes == 5000
    assert chi2(written.values, given.edges, given.priors) < chi2(
        given.values, given.edges, given.priors
    )


def _an_accepted_step(progress: bytes) -> bool:
    """Whether a progress table holds the whole line of an iteration that was not rejected."""
    lines = progress.decode().splitlines()[:-1]  # the last may be partial
    return any(re.match(r"\s*\d+ ", line) and not line.endswith("(rejected)") for line in lines)


def _read_available(descriptor: int) -> bytes:
    """What a pseudo-terminal holds, b"" once its other end is closed and drained."""
    try:
        return os.read(descriptor, 4096)
    except OSError:
        return b""


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
        f"1 line(s) skipped: 1 × EDGE_SE2: edge from node 5 to itself (first at line {last})"
        in problems
    )
    text = run("info", broken, "--lenient").stdout
    assert "→" in text  # every problem comes with a suggestion


def test_every_command_reports_the_lines_that_lenient_reading_skipped(tmp_path):
    """--lenient leaves lines out of every result: text mode says so on stderr before any work,
    JSON lists them by file and reason (``skipped_lines``), and --quiet prints nothing."""
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
    assert text.stderr == warning and "wrote" in text.stdout
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

    import posegraph.scale_drift

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

    optimize = posegraph.optimize
    monkeypatch.setattr(posegraph, "optimize", no_work)
    monkeypatch.setattr(posegraph.scale_drift, "optimize", no_work)
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
    monkeypatch.setattr(posegraph, "optimize", optimize)
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
    """In a graph that GNC left, the rejected loops are dashed red segments between the poses
    they join, the rejected fixes red circles at their measured positions, and the graph's
    label counts the rejected loops; the graph before the run draws every loop alike."""
    from posegraph import optimize, plotting

    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    before = corrupted.copy()
    optimize(corrupted, robust="gnc", robust_priors=True)
    figures = []
    monkeypatch.setattr(plotting, "save_figure", lambda figure, path: figures.append(figure))
    plotting.plot_graphs([("initial", before), ("optimised", corrupted)], "x.png")
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


def test_drop_rejected_writes_the_inliers(tmp_path):
    """`--drop-rejected` leaves the loops that `--robust` rejected out of -o's graph, and the
    report says so; it is refused without --robust, without -o, or when -o holds poses only."""
    graph, _ = city_with_fixes(0.0, seed=0)
    corrupted, false = add_false_loops(graph, 0.1, seed=0)
    path, out = tmp_path / "false_loops.g2o", tmp_path / "inliers.g2o"
    write_graph(corrupted, str(path))
    text = run("optimize", path, "--robust", "gnc", "-o", out, "--drop-rejected").stdout
    assert f"wrote           {out} (without the {false.sum()} rejected edge(s))" in text
    written = read_graph(str(out)).graph
    np.testing.assert_array_equal(written.node_ids, corrupted.node_ids)
    np.testing.assert_array_equal(written.edges.i, corrupted.edges.i[~false])
    np.testing.assert_array_equal(written.edges.j, corrupted.edges.j[~false])
    kept = read_graph(str(path)).graph.num_edges
    assert run_json("optimize", path, "--robust", "gnc", "-o", out)["edges"] == kept
    for extra, message in [
        (["-o", out], "--drop-rejected needs --robust: only a robust run rejects measurements"),
        (["--robust", "gnc"], "--drop-rejected leaves the rejected edges out of the graph that -o"),
        (["--robust", "gnc", "-o", tmp_path / "poses.tum"], f"{tmp_path / 'poses.tum'}: --drop"),
    ]:
        refused = run("optimize", path, "--drop-rejected", *extra, check_exit=2)
        assert f"posegraph: error: {message}" in refused.stderr


def test_eval_reports_ate_and_rpe(tmp_path):
    from posegraph_datasets.generators import sphere

    from posegraph.trajectory_io import Trajectory, write_trajectory

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
    from posegraph.trajectory_io import Trajectory, write_trajectory

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


def test_numbers_that_overflow_are_reported_and_nothing_is_written(tmp_path):
    """A vertex at 1e200: its residuals' squares overflow, so the error is ∞ at the file's
    values, from which ``--init file`` cannot move. (An edge that large is refused on its line:
    the malformed corpus.)"""
    lines = open(EXAMPLE_2D).read().splitlines()
    vertex = next(k for k, line in enumerate(lines) if line.startswith("VERTEX_SE2 5 "))
    fields = lines[vertex].split()
    fields[2] = "1e200"
    lines[vertex] = " ".join(fields)
    huge, out = tmp_path / "huge.g2o", tmp_path / "out.g2o"
    huge.write_text("\n".join(lines) + "\n")
    failed = run("optimize", huge, "-o", out, "--init", "file", check_exit=2)
    assert "the optimisation ended with error" in failed.stderr
    assert "Nothing written" in failed.stderr and "Warning" not in failed.stderr
    assert not out.exists()
    diagnosis = run_json("info", huge)
    assert diagnosis["initial_error"] is None  # not finite: JSON has no ∞
    problems = [problem["what"] for problem in diagnosis["problems"]]
    assert any("residuals overflow" in problem for problem in problems)
    # The first-order test cannot be made where the Jacobians overflow: no false finding.
    assert not any("move together" in problem for problem in problems), problems


def test_an_initialisation_beyond_double_precision_is_reported_naming_the_file(tmp_path):
    """Sim3 odometry that multiplies the scale by e^200 at every step (``sim3_scale_chain``):
    composed from the first pose, the fifth and sixth lie beyond double precision. One line
    names the file and the nodes."""
    source, out = tmp_path / "scales.g2o", tmp_path / "out.g2o"
    write_graph(sim3_scale_chain(), str(source))
    failed = run("optimize", source, "-o", out, check_exit=2)
    assert failed.stderr == (
        f"posegraph: error: {source}: the odometry initialisation composes the measurements to"
        " values beyond double precision at nodes 4, 5: a translation or scale too large to"
        " hold\n"
    )
    assert not out.exists()


def test_numeric_arguments_are_checked_by_the_parser():
    """Counts and limits out of range stop at parsing (exit 2), naming the argument."""
    cases = [
        (["optimize", EXAMPLE, "--max-iterations", "-3"], "--max-iterations: must be ≥ 0"),
        (["optimize", EXAMPLE, "--time-limit", "-1"], "--time-limit: must be ≥ 0"),
        (["optimize", EXAMPLE, "--max-iterations", "x"], "--max-iterations: not an integer"),
        (["eval", EXAMPLE, EXAMPLE, "--delta", "0"], "--delta: must be ≥ 1"),
        (
            ["eval", EXAMPLE, EXAMPLE, "--max-time-difference", "-0.1"],
            "--max-time-difference: must be ≥ 0",
        ),
        (["bench", "--repeats", "0"], "--repeats: must be ≥ 1"),
        (["bench", "--rounds", "0"], "--rounds: must be ≥ 1"),
        (["bench", "--budget", "-0.5"], "--budget: must be ≥ 0"),
        (
            ["scale-drift", EXAMPLE, "--scale-information", "0"],
            "must be positive and finite, not 0",
        ),
        (["info", EXAMPLE, "--scale-information", "-1"], "must be positive and finite, not -1"),
        (
            ["optimize", EXAMPLE, "--scale-information", "nan"],
            "must be positive and finite, not nan",
        ),
    ]
    for args, message in cases:
        failed = run(*args, check_exit=2)
        assert message in failed.stderr and "Traceback" not in failed.stderr, args


def test_an_internal_error_is_one_line(monkeypatch, capsys):
    """A crash is reported as its first line only (a message can span pages, as gtsam's do)."""
    from posegraph_cli import commands, main

    def crash(args):
        raise RuntimeError("first line\n" + "page of detail\n" * 100)

    monkeypatch.setattr(commands, "info", crash)
    assert main.main(["info", EXAMPLE]) == main.EXIT_INTERNAL
    stderr = capsys.readouterr().err
    assert stderr == (
        "posegraph: error: internal error: RuntimeError: first line (rerun with --debug)\n"
    )


def test_with_json_a_stop_is_a_document_on_stdout_too(tmp_path, monkeypatch, capsys):
    """A script that reads stdout learns why a command stopped: the stderr line, the exit code,
    and the file and line at fault, where there is one."""
    from posegraph_cli import commands, main
    from posegraph_cli.schema import ERROR

    bad = tmp_path / "bad.g2o"
    bad.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0 0\n")
    unreadable = tmp_path / "folder.g2o"
    unreadable.mkdir()
    folder = tmp_path / "folder.png"
    folder.mkdir()
    nowhere = tmp_path / "no" / "f.png"

    def crash(args):
        raise RuntimeError("first line")

    cases = [
        (["info", str(bad)], "bad_input", 2, str(bad), 2),
        (["optimize", str(unreadable)], "bad_input", 2, str(unreadable), None),
        (["optimize", EXAMPLE, "-o", EXAMPLE], "bad_input", 2, EXAMPLE, None),
        (["plot", EXAMPLE, "-o", str(nowhere)], "bad_input", 2, str(nowhere), None),
        (
            ["plot", EXAMPLE, "-o", str(tmp_path / "f.xyz")],
            "bad_input",
            2,
            str(tmp_path / "f.xyz"),
            None,
        ),
        (
            ["optimize", EXAMPLE, "-o", str(tmp_path / "g.xyz")],
            "bad_input",
            2,
            str(tmp_path / "g.xyz"),
            None,
        ),
        (["eval", EXAMPLE, EXAMPLE, "--plot", str(folder)], "bad_input", 2, str(folder), None),
        (["eval", EXAMPLE, str(bad)], "bad_input", 2, str(bad), 2),
        (["convert", EXAMPLE, str(tmp_path / "poses.tum")], "internal", 3, None, None),
    ]
    monkeypatch.setattr(commands, "convert", crash)
    for args, kind, exit_code, path, line in cases:
        assert main.main([*args, "--json"]) == exit_code, args
        captured = capsys.readouterr()
        document = json.loads(captured.out)
        jsonschema.validate(document, ERROR)
        error = document["error"]
        assert document["command"] == args[0], args
        assert (error["kind"], error["exit_code"], error["path"], error["line"]) == (
            kind,
            exit_code,
            path,
            line,
        ), args
        assert captured.err == f"posegraph: error: {error['message']}\n", args
        main.main(args)
        assert capsys.readouterr().out == "", args  # without --json, nothing on stdout


@pytest.mark.parametrize("name, content, line, words", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_input_gives_one_line_and_exit_2(tmp_path, name, content, line, words):
    path = write_case(tmp_path, name, content)
    completed = run("optimize", path, "-o", tmp_path / "out.g2o", check_exit=2)
    assert completed.stderr.count("\n") == 1, completed.stderr
    assert "Traceback" not in completed.stderr and words in completed.stderr
    assert str(path) in completed.stderr
    assert not (tmp_path / "out.g2o").exists()


@pytest.mark.parametrize("command", ["info", "convert", "plot"])
@pytest.mark.parametrize("case", [0, 3, 7, 11, 13, 17], ids=lambda k: MALFORMED[k][0])
def test_malformed_input_for_other_commands(tmp_path, command, case):
    name, content, _, words = MALFORMED[case]
    path = write_case(tmp_path, name, content)
    extra = {"info": [], "convert": [tmp_path / "o.graph"], "plot": ["-o", tmp_path / "o.png"]}[
        command
    ]
    completed = run(command, path, *extra, check_exit=2)
    assert completed.stderr.count("\n") == 1 and words in completed.stderr
    assert "Traceback" not in completed.stderr


def test_debug_shows_the_traceback(tmp_path):
    path = write_case(tmp_path, *MALFORMED[0][:2])
    assert "Traceback" in run("info", path, "--debug", check_exit=2).stderr


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

    from posegraph.evaluation import segment_drift
    from posegraph.trajectory_io import Trajectory, write_trajectory

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
    from posegraph.lifting import default_scale_information

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
