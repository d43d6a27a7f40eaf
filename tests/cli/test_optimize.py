"""``posegraph optimize``, driven as a subprocess the way a new user runs it."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import re
import shutil
import signal
import struct
import subprocess
import sys
import termios

import numpy as np
import pytest
from posegraph_datasets.outliers import add_false_loops

from posegraph.io import read_graph, write_graph
from posegraph.lie import SE3
from posegraph.problem.factors import chi2
from posegraph.robust.spec import robust_mask
from tests.cli.helpers import (
    COMMAND,
    EXAMPLE,
    EXAMPLE_2D,
    assert_not_blank,
    monocular_file,
    run,
    run_json,
)

from ..conftest import city_with_fixes, maps_joined_by_positions


def _a_step_below(progress: bytes, error: float) -> bool:
    """Whether the progress line showed a cost below ``error`` (beyond its seven digits): a
    step was accepted."""
    shown = re.findall(r"½Σ rᵀΩr ([-+.e\d]+) ·", progress.decode(errors="replace"))
    return any(float(cost) < error * (1 - 1e-6) for cost in shown)


def _read_available(descriptor: int) -> bytes:
    """What a pseudo-terminal holds, b"" once its other end is closed and drained."""
    try:
        return os.read(descriptor, 4096)
    except OSError:
        return b""


def test_version_and_help():
    assert run("--version").stdout.startswith("posegraph ")
    for command in ("optimize", "info", "convert", "plot", "eval", "bench"):
        text = run(command, "--help").stdout
        assert "examples:" in text and f"posegraph {command}" in text


def _modules_loaded_by(*arguments: str) -> set[str]:
    """The modules that a ``posegraph`` process with ``arguments`` has loaded when it ends."""
    probe = (
        "import contextlib, io, sys, posegraph_cli.main\n"
        "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
        f"    posegraph_cli.main.main({list(arguments)!r})\n"
        "print(' '.join(sorted(sys.modules)))"
    )
    return set(
        subprocess.run(
            [sys.executable, "-c", probe], capture_output=True, text=True, check=True
        ).stdout.split()
    )


def test_start_up_leaves_plotting_and_statistics_unloaded():
    """matplotlib and scipy.stats each add about 0.4 s to a start, scipy.special 0.05 s; only
    plotting needs the first, only robust statistics the last."""
    loaded = _modules_loaded_by("--version")
    assert "posegraph.api" in loaded
    assert not {"matplotlib", "scipy.stats", "scipy.special"} & loaded


@pytest.mark.parametrize("example", [EXAMPLE, EXAMPLE_2D])
@pytest.mark.parametrize("shown", [[], ["-q"]])
def test_an_optimisation_with_cholmod_never_imports_scipy(tmp_path, example, shown):
    """Importing any of scipy's subpackages costs about 0.3 s (scipy 1.17's array-API layer
    imports numpy.f2py and numpy.testing), a third of a quiet start on sphere2500: an SE2 or
    SE3 optimisation with CHOLMOD, written to a file, with its summary (and noise check) or
    quiet, does without it."""
    pytest.importorskip("cvxopt")
    output = str(tmp_path / "out.g2o")
    loaded = _modules_loaded_by("optimize", str(example), "-o", output, *shown)
    assert (tmp_path / "out.g2o").exists()
    assert "posegraph.smoother.smoother" in loaded
    assert not {name for name in loaded if name.split(".")[0] == "scipy"}


def test_optimize_the_bundled_example(tmp_path):
    out, figure = tmp_path / "out.g2o", tmp_path / "out.png"
    document = run_json("optimize", EXAMPLE, "-o", out, "--plot", figure)
    summary = document["summary"]
    assert summary["converged"] and summary["final_error"] < summary["initial_error"]
    assert read_graph(str(out)).graph.num_nodes == document["nodes"] == 160
    assert_not_blank(figure)
    # Piped output: a readable summary on stdout, and on stderr one plain line per solve.
    text = run("optimize", EXAMPLE)
    assert "termination" in text.stdout and "error ½Σrᵀ Ω r" in text.stdout
    assert re.fullmatch(r"iterating +[\d.]+ s it \d+/100 · ½Σ rᵀΩr [\d.]+ · λ \S+\n", text.stderr)
    assert run("optimize", EXAMPLE, "--quiet").stdout == ""


def test_covariances_of_every_pose_equal_gtsams(tmp_path):
    """``--covariances`` writes each pose's marginal covariance at the optimum, which must equal
    gtsam.Marginals at the optimised graph's values (1e-6 relative; gtsam holds the gauge node
    with a σ = 1e-6 prior); the gauge node's is zero."""
    gtsam = pytest.importorskip("gtsam")
    from posegraph.lie.gtsam_order import matrix_from_gtsam
    from posegraph.validation.gtsam_bridge import graph_to_gtsam

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


def _terminal(
    arguments: list, exit_code: int = 0, rows: int = 40, columns: int = 100
) -> tuple[list[str], str]:
    """Run the command on a pseudo-terminal of ``rows`` × ``columns``; (the screen it leaves,
    rendered by a VT100 emulator, and everything it wrote, escapes and all)."""
    pyte = pytest.importorskip("pyte")
    main, secondary = pty.openpty()
    fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))
    process = subprocess.Popen(
        [*COMMAND, *map(str, arguments)], stdin=secondary, stdout=secondary, stderr=secondary
    )
    os.close(secondary)
    output = b""
    while chunk := _read_available(main):
        output += chunk
    os.close(main)
    assert process.wait(timeout=300) == exit_code, output.decode()
    screen = pyte.Screen(columns, rows)
    stream = pyte.Stream(screen)
    text = output.decode().replace("\r\n", "\n").replace("\n", "\r\n")  # the pty's ONLCR
    stream.feed(text)
    return [line.rstrip() for line in screen.display if line.strip()], output.decode()


def _stage_lines(screen: list[str]) -> list[str]:
    """The progress lines left on the screen: each stage's, ticked when it ended."""
    return [line for line in screen if line.startswith("✓ ")]


@pytest.mark.parametrize(
    "options",
    [[], ["--robust", "gnc"], ["--solver", "dogleg"]],
    ids=["least squares", "gnc", "dogleg"],
)
@pytest.mark.parametrize("command", ["optimize", "scale-drift"])
def test_progress_is_one_updating_line_per_stage(tmp_path, command, options):
    """Under a pseudo-terminal, optimize and scale-drift leave one line per stage, not a line
    per iteration; it shows the iteration, the cost the stage minimises and λ (the dogleg's
    trust-region radius); a robust run's stages minimise a weighted cost."""
    source = EXAMPLE if command == "optimize" else monocular_file(tmp_path)[0]
    screen, output = _terminal([command, source, *options])
    stages = _stage_lines(screen)
    names = [line[2:26].strip() for line in stages]
    assert len(names) == len(set(names)), stages  # one line per stage
    assert "initialising" in names
    damping = "radius" if "dogleg" in options else "λ"
    iterating = [line for line in stages if " it " in line]
    whole = [line for line in iterating if not line.endswith("…")]  # not cut to the width
    assert whole and all(damping in line for line in whole), stages
    if "--robust" in options:
        assert "least squares" in names and "iterating" not in names, stages
        assert all("½Σ w rᵀΩr" in line for line in iterating)
    else:
        assert "iterating" in names
        assert re.search(r"it \d+/100 · ½Σ rᵀΩr", output)


def test_progress_on_torus3d_and_gnc_with_false_loops_does_not_scroll(tmp_path, shared_dataset):
    """The acceptance runs: torus3D from the file's values (many iterations), and GNC on a
    graph with false loops: a screen of a few stage lines, each updated in place as its stage
    ran (the output held many states of it), not a log of iterations. GNC's rounds share a
    line per start (warm, chordal)."""
    torus = shared_dataset("torus3D.g2o")
    arguments = ["optimize", torus, "--init", "file", "--max-iterations", "15"]
    screen, output = _terminal(arguments, exit_code=1)  # not converged in 15
    assert [line[2:26].strip() for line in _stage_lines(screen)] == [
        "reading torus3D.g2o",
        "initialising",
        "iterating",
    ]
    assert "it 15/15" in _stage_lines(screen)[-1]
    assert len(set(re.findall(r"it (\d+)/15", output))) > 5  # updated as it ran

    graph, _ = add_false_loops(read_graph(EXAMPLE_2D).graph, 0.2, seed=3)
    loops = tmp_path / "false_loops.g2o"
    write_graph(graph, str(loops))
    screen, output = _terminal(["optimize", loops, "--robust", "gnc"])
    stages = _stage_lines(screen)
    rounds = {int(r) for r in re.findall(r"round (\d+)", output)}  # as the line was redrawn
    gnc = [line for line in stages if line.startswith(("✓ gnc (chordal) ", "✓ gnc (warm) "))]
    last = max(int(re.search(r"round (\d+)", line)[1]) for line in gnc)
    assert gnc[0].startswith("✓ gnc (chordal) ")
    assert len(rounds) >= 2 and last == max(rounds) > 5 and len(stages) < 12, stages


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
    what to do, and --calibrate-noise takes the true ones back. With the file's information,
    where only the false loops go, it does not."""
    graph, _ = city_with_fixes(0.0, seed=0)
    corrupted, false = add_false_loops(graph, 0.1, seed=0)
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
    assert "--calibrate-noise estimates it" in text
    assert "widen the kernel (--robust gnc:WIDTH)" in text
    calibrated = run_json("optimize", path, "--robust", "gnc", "--calibrate-noise")["summary"]
    rejected = np.asarray(calibrated["rejected_edges"])
    assert set(rejected) == set(np.flatnonzero(false))


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
    given = read_graph(source).graph
    initial = 0.5 * chi2(given.values, given.edges, given.priors)
    while not _a_step_below(progress, initial) and (chunk := _read_available(main)):
        progress += chunk
    process.send_signal(signal.SIGINT)
    stdout, _ = process.communicate(timeout=120)
    while chunk := _read_available(main):
        progress += chunk
    os.close(main)
    assert process.returncode == 1, progress.decode()
    assert "Traceback" not in progress.decode()
    assert "interrupted (Ctrl-C)" in stdout
    written = read_graph(str(out)).graph
    assert written.num_nodes == given.num_nodes == 5000
    assert chi2(written.values, given.edges, given.priors) < chi2(
        given.values, given.edges, given.priors
    )


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


def test_calibrate_noise_reports_the_scales_and_writes_the_scaled_information(tmp_path):
    """A graph whose information states 100× its noise: the report names the overstatement,
    --calibrate-noise scales it back, says so in text and JSON, and -o holds it scaled."""
    from posegraph_datasets.generators import manhattan_world

    graph, _ = manhattan_world(300, seed=4)
    path, out = tmp_path / "scaled.g2o", tmp_path / "out.g2o"
    write_graph(graph.weighted(np.full(graph.num_edges, 1e-2)), path)
    text = run("optimize", path).stdout
    assert re.search(r"noise +χ² per redundant dof odometry 0\.0\d", text)
    assert "overstates their noise about" in text and "--calibrate-noise" in text
    summary = run_json("optimize", path, "--calibrate-noise", "-o", out)["summary"]
    calibration = summary["calibration"]
    assert calibration["automatic"] is False and calibration["solves"] >= 1
    assert all(60 < scale < 140 for scale in calibration["scales"].values())
    assert all(abs(c["chi2_per_dof"] - 1) < 0.3 for c in summary["noise"])
    written = read_graph(str(out)).graph
    factor = written.edges.information[0, 0, 0] / (1e-2 * graph.edges.information[0, 0, 0])
    assert factor == pytest.approx(calibration["scales"]["odometry"], rel=1e-6)
    text = run("optimize", path, "--calibrate-noise").stdout
    assert re.search(r"calibrated +information odometry ×\d+", text)


def test_the_summary_says_why_robust_mode_calibrated():
    """Automatic calibration names its reason: gross outliers kept, rejections that the noise
    of the kept measurements explains, or a second opinion at a narrower width
    (``robust.second_opinion``) taken."""
    import dataclasses

    from posegraph_cli.summary import _noise_lines
    from posegraph_datasets.generators import manhattan_world

    import posegraph

    graph, _ = manhattan_world(30, seed=4)
    summary = posegraph.optimize(graph, robust="gnc").summary
    assert summary.noise and summary.calibration is None
    reasons = [
        (False, 0, "GNC kept gross outliers"),
        (False, 12, "GNC rejected 12 measurements that the noise of those it kept explains"),
        (True, 0, "a tenth of the width"),
    ]
    for second, consistent, reason in reasons:
        calibration = {"scales": {"odometry": 400.0}, "automatic": True, "solves": 3}
        calibration |= {"second_opinion": second, "consistent_rejections": consistent}
        calibrated = dataclasses.replace(summary, calibration=calibration)
        (line,) = [line for line in _noise_lines(calibrated) if "calibrated" in line]
        assert reason in line and "odometry ×400" in line
