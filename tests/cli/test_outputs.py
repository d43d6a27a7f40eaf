"""What the commands promise about their files: no input is replaced by an output, two outputs
are never one file, all outputs are written or none, devices and FIFOs are written through,
and Ctrl-C at any point gives one line, keeping a converged result."""

from __future__ import annotations

import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import threading
import time

import numpy as np
import posegraph_cli.main as cli
import pytest
from posegraph_cli.schema import ERROR

from posegraph.io import read_graph

from .helpers import COMMAND, EXAMPLE, jsonschema, monocular_file, run


def _digest(path) -> bytes:
    return open(path, "rb").read()


@pytest.mark.parametrize(
    "arguments, flag",
    [
        (("scale-drift", "{mono}", "-o", "{gt}", "--gt", "{gt}"), "-o"),
        (("optimize", "{png}", "--plot", "{png}"), "--plot"),
        (("eval", "{gt}", "{gt}", "--plot", "{gt}"), "--plot"),
        (("plot", "{mono}", "{png}", "-o", "{png}"), "-o"),
    ],
)
def test_no_output_replaces_an_input(tmp_path, arguments, flag):
    """Every path a command reads is protected from every path it writes (``--plot`` too, and
    ``--gt`` from ``-o``, which ``--overwrite`` does not change)."""
    mono, gt, _ = monocular_file(tmp_path)
    png = tmp_path / "graph.png"
    shutil.copy(mono, png)  # a graph file that happens to end in .png
    names = {"mono": mono, "gt": gt, "png": png}
    before = {name: _digest(path) for name, path in names.items()}
    extra = ("--overwrite",) if arguments[0] == "scale-drift" else ()
    completed = run(*[a.format(**names) for a in arguments], *extra, check_exit=2)
    assert len(completed.stderr.splitlines()) == 1
    assert f"refusing to overwrite an input file with {flag}" in completed.stderr
    assert {name: _digest(path) for name, path in names.items()} == before


def test_two_outputs_are_never_one_file(tmp_path):
    out = tmp_path / "out.g2o"
    completed = run("optimize", EXAMPLE, "-o", out, "--covariances", out, check_exit=2)
    assert "-o and --covariances name the same file" in completed.stderr
    assert not out.exists()
    link = tmp_path / "link.g2o"
    os.symlink(out, link)  # the same file under another name
    completed = run("optimize", EXAMPLE, "-o", out, "--covariances", link, check_exit=2)
    assert "name the same file" in completed.stderr and not out.exists()


def test_overwrite_allows_the_graph_input_only_to_be_replaced(tmp_path):
    source = tmp_path / "in.g2o"
    shutil.copy(EXAMPLE, source)
    refused = run("optimize", source, "-o", source, check_exit=2)
    assert "pass --overwrite to allow it" in refused.stderr
    run("optimize", source, "-o", source, "--overwrite")
    assert read_graph(str(source)).graph.num_nodes == 160


def _full_device(tmp_path) -> str:
    """A device whose writes fail for want of space: a private /dev/full node as root (a
    broken build cannot replace the machine's), else /dev/full itself."""
    if os.geteuid() == 0:
        device = tmp_path / "devices" / "full"
        device.parent.mkdir()
        os.mknod(device, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
        return str(device)
    if not stat.S_ISCHR(os.stat("/dev/full").st_mode):
        pytest.skip("needs /dev/full")
    return "/dev/full"


def test_disk_full_names_the_path_and_replaces_no_output(tmp_path):
    """A failing output (``/dev/full``: no space) stops the command with exit 2 naming it; the
    graph that ``-o`` would have written is not left behind."""
    full = _full_device(tmp_path)
    out = tmp_path / "out.g2o"
    completed = run("optimize", EXAMPLE, "-o", out, "--covariances", full, "--json", check_exit=2)
    error = json.loads(completed.stdout)["error"]
    assert error["path"] == full and "No space left on device" in error["message"]
    assert not out.exists() and set(os.listdir(tmp_path)) <= {"devices"}
    completed = run("convert", EXAMPLE, full, "--to", "g2o", check_exit=2)
    assert completed.stderr.strip().endswith(f"{full}: cannot write: No space left on device")
    assert stat.S_ISCHR(os.stat(full).st_mode)


def test_a_fifo_is_written_through_not_replaced(tmp_path):
    fifo = tmp_path / "pipe.g2o"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(_digest(fifo)))
    reader.start()
    run("convert", EXAMPLE, fifo)
    reader.join(timeout=60)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert received and received[0].decode().count("EDGE_SE3:QUAT") == 299


def test_a_symlink_is_followed_and_kept(tmp_path):
    target, link = tmp_path / "real.g2o", tmp_path / "link.g2o"
    target.write_text("old\n")
    os.symlink(target, link)
    run("convert", EXAMPLE, link)
    assert os.path.islink(link) and read_graph(str(target)).graph.num_nodes == 160
    to_stdout = tmp_path / "stdout.g2o"
    os.symlink("/proc/self/fd/1", to_stdout)
    completed = run("convert", EXAMPLE, to_stdout, "--quiet")
    assert os.path.islink(to_stdout) and completed.stdout.count("VERTEX_SE3:QUAT") == 160


@pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")
def test_a_device_is_written_through_not_replaced(tmp_path):
    device = tmp_path / "null"
    os.mknod(device, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # /dev/null's numbers
    run("convert", EXAMPLE, device, "--to", "g2o")
    assert stat.S_ISCHR(os.lstat(device).st_mode)


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def _main(argv: list[str]) -> int:
    """``posegraph`` in this process; a Ctrl-C that escapes it fails the test (and does not
    stop pytest)."""
    try:
        return cli.main(argv)
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped the command as a KeyboardInterrupt (a traceback)")


def test_ctrl_c_while_reading_gives_one_line_and_exit_130(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("posegraph_cli.common.load_graph", _interrupt)
    out = tmp_path / "out.g2o"
    assert _main(["optimize", EXAMPLE, "-o", str(out)]) == 130
    assert capsys.readouterr().err == "posegraph: error: interrupted (Ctrl-C); nothing written\n"
    assert not out.exists()
    assert _main(["info", EXAMPLE, "--json"]) == 130  # a script reading stdout is told too
    document = json.loads(capsys.readouterr().out)
    jsonschema.validate(document, ERROR)
    assert document["command"] == "info" and document["error"]["kind"] == "interrupted"


def test_ctrl_c_while_converting_writes_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("posegraph.io.writer.format_g2o", _interrupt)
    out = tmp_path / "out.g2o"
    assert _main(["convert", EXAMPLE, str(out)]) == 130
    assert len(capsys.readouterr().err.splitlines()) == 1
    assert os.listdir(tmp_path) == []


def test_ctrl_c_during_covariances_keeps_the_converged_graph(tmp_path, monkeypatch, capsys):
    """The optimised graph is written before a later phase can lose it: exit 1 (the best values
    were written), one line naming what was written (after the solve's progress line)."""
    monkeypatch.setattr("posegraph.marginals", _interrupt)
    out, covariances = tmp_path / "out.g2o", tmp_path / "cov.txt"
    assert _main(["optimize", EXAMPLE, "-o", str(out), "--covariances", str(covariances)]) == 1
    progress, err = capsys.readouterr().err.split("\n", 1)
    assert progress.startswith("iterating ")
    assert err == f"posegraph: error: interrupted (Ctrl-C): wrote {out}; the rest was not written\n"
    assert read_graph(str(out)).graph.num_nodes == 160 and not covariances.exists()
    assert sorted(os.listdir(tmp_path)) == ["out.g2o"]


def test_ctrl_c_during_imports_gives_one_line():
    """The entry point handles Ctrl-C before it imports the library."""
    probe = (
        "import sys\n"
        "class Stop:\n"
        "    def find_spec(self, name, *args):\n"
        "        if name == 'posegraph': raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Stop())\n"
        "import posegraph_cli.main\n"
        "sys.exit(posegraph_cli.main.main(['info', 'x.g2o']))\n"
    )
    completed = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert completed.returncode == 130
    assert completed.stderr == "posegraph: error: interrupted (Ctrl-C); nothing written\n"


def _past_interpreter_start(process: subprocess.Popen) -> None:
    """Waits until ``process`` has mapped numpy's core extension, which the command imports: a
    SIGINT during the interpreter's own start (its ``site`` module) ends it with a fatal error
    before any of posegraph's code runs, which a loaded machine can make last 0.2 s, and one
    while that extension initialises becomes numpy's ImportError, whose message quotes a
    traceback."""
    maps = f"/proc/{process.pid}/maps"
    for _ in range(2000):
        try:
            with open(maps) as mapped:
                if "_multiarray_umath" in mapped.read():
                    return
        except FileNotFoundError:
            return
        time.sleep(0.005)


def test_a_real_sigint_never_prints_a_traceback(tmp_path):
    """SIGINT at some point of ``info`` on a larger graph, from just after numpy's core is
    loaded: one line and 130, or done. The delays sweep the libraries' imports, inside which a
    KeyboardInterrupt can be lost (``posegraph_cli.main._interrupts``)."""
    from posegraph_datasets.generators import manhattan_world

    from posegraph.io import write_graph

    source = tmp_path / "big.g2o"
    write_graph(manhattan_world(20000, seed=1)[0], str(source))
    for delay in np.arange(0.1, 1.0, 0.1):
        process = subprocess.Popen(
            [*COMMAND, "info", str(source)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        _past_interpreter_start(process)
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=120)
        assert "Traceback" not in err
        assert process.returncode in (0, 130), err
        if process.returncode == 130:
            assert err.splitlines()[-1] == "posegraph: error: interrupted (Ctrl-C); nothing written"


def test_outputs_hold_no_non_finite_number(tmp_path):
    out = tmp_path / "out.g2o"
    run("optimize", EXAMPLE, "-o", out)
    numbers = [float(x) for line in open(out) for x in line.split()[1:]]
    assert np.isfinite(numbers).all()
