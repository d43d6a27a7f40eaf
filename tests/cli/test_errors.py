"""Bad input and crashes at the command line: one line, the right exit code, a JSON document with
``--json``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from posegraph.io import write_graph
from tests.cli.helpers import EXAMPLE, EXAMPLE_2D, jsonschema, run, run_json

from ..conftest import sim3_scale_chain
from ..io.malformed import MALFORMED
from ..io.test_malformed import write_case


def test_numbers_that_overflow_are_reported_and_nothing_is_written(tmp_path):
    """A vertex at 1e200: its edges' errors overflow at the file's values. ``info`` said
    "initial error inf" with exit 0 and ``optimize --init file`` stopped after the read; now
    the first such edge is refused on its line, and ``--lenient`` (and ``info``) leave those
    edges out."""
    lines = open(EXAMPLE_2D).read().splitlines()
    vertex = next(k for k, line in enumerate(lines) if line.startswith("VERTEX_SE2 5 "))
    fields = lines[vertex].split()
    fields[2] = "1e200"
    lines[vertex] = " ".join(fields)
    huge, out = tmp_path / "huge.g2o", tmp_path / "out.g2o"
    huge.write_text("\n".join(lines) + "\n")
    first_edge = next(
        k + 1 for k, line in enumerate(lines) if line.startswith(("EDGE_SE2 5 ", "EDGE_SE2 4 5 "))
    )
    failed = run("optimize", huge, "-o", out, "--init", "file", check_exit=2)
    assert failed.stderr.startswith(f"posegraph: error: {huge}:{first_edge}: EDGE_SE2: its")
    assert "error at the file's values overflows" in failed.stderr
    assert len(failed.stderr.splitlines()) == 1 and not out.exists()
    diagnosis = run_json("info", huge)  # lenient: the edges are a problem it lists
    assert np.isfinite(diagnosis["initial_error"])
    assert any(
        p["what"].startswith(f"3 line(s) skipped (first at line {first_edge})")
        for p in diagnosis["problems"]
    )
    document = run_json("optimize", huge, "--lenient", "-o", out, check_exit=None)
    skipped = document["skipped_lines"][0]
    assert skipped["first_line"] == first_edge and skipped["count"] == 3
    assert np.isfinite([float(x) for x in out.read_text().split() if x[0] in "-0123456789"]).all()


def test_an_initialisation_beyond_double_precision_is_reported_naming_the_file(tmp_path):
    """Sim3 odometry that multiplies the scale by e^100 at every step (``sim3_scale_chain``):
    composed from the first pose, the ninth to eleventh lie beyond double precision. One line
    names the file and the nodes."""
    source, out = tmp_path / "scales.g2o", tmp_path / "out.g2o"
    write_graph(sim3_scale_chain(), str(source))
    failed = run("optimize", source, "-o", out, check_exit=2)
    assert failed.stderr == (
        f"posegraph: error: {source}: the odometry initialisation composes the measurements to"
        " values beyond double precision at nodes 8, 9, 10: a translation or scale too large to"
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
        (["optimize", str(bad)], "bad_input", 2, str(bad), 2),
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


@pytest.mark.parametrize("command", ["convert", "plot"])
@pytest.mark.parametrize("case", [0, 3, 7, 11, 13, 17], ids=lambda k: MALFORMED[k][0])
def test_malformed_input_for_other_commands(tmp_path, command, case):
    name, content, _, words = MALFORMED[case]
    path = write_case(tmp_path, name, content)
    extra = {"convert": [tmp_path / "o.graph"], "plot": ["-o", tmp_path / "o.png"]}[command]
    completed = run(command, path, *extra, check_exit=2)
    assert completed.stderr.count("\n") == 1 and words in completed.stderr
    assert "Traceback" not in completed.stderr


@pytest.mark.parametrize("case", [0, 3, 7, 11, 13, 17], ids=lambda k: MALFORMED[k][0])
def test_info_lists_what_other_commands_refuse(tmp_path, case):
    """``info`` reads leniently: a bad line is a problem it lists, with its line; only a file
    with nothing readable stops it (one line, exit 2)."""
    name, content, line, words = MALFORMED[case]
    path = write_case(tmp_path, name, content)
    completed = run("info", path, "--json", check_exit=None)
    if completed.returncode == 0:
        problems = " | ".join(p["what"] for p in json.loads(completed.stdout)["problems"])
        assert words in problems and f"(first at line {line})" in problems
    else:
        assert completed.returncode == 2 and completed.stderr.count("\n") == 1
        assert words in completed.stderr and "Traceback" not in completed.stderr


def test_debug_shows_the_traceback(tmp_path):
    path = write_case(tmp_path, *MALFORMED[0][:2])
    assert "Traceback" in run("info", path, "--debug", check_exit=2).stderr


def test_a_lenient_stop_prints_one_line(tmp_path):
    """The report of skipped lines waits for the results: a command that then stops (here the
    initialisation overflows) prints its error alone, not a warning and an error."""
    source = tmp_path / "scales.g2o"
    write_graph(sim3_scale_chain(), str(source))
    with open(source, "a") as file:
        file.write("EDGE_SIM3:QUAT 0 1 x\n")
    failed = run("optimize", source, "--lenient", check_exit=2)
    assert len(failed.stderr.splitlines()) == 1 and "beyond double precision" in failed.stderr
    example = tmp_path / "example.g2o"
    example.write_text(open(EXAMPLE).read() + "EDGE_SE3:QUAT 0 1 x\n")
    warned = run("optimize", example, "--lenient")  # a run that ends well still warns
    progress, warning = warned.stderr.split("\n", 1)  # after the solve's progress line
    assert progress.startswith("iterating ")
    assert warning.startswith(f"posegraph: warning: {example}: 1 line(s) skipped")
