"""Every command's ``--help`` examples run as written, in order, in an empty folder: the graphs
they use are the ones ``posegraph generate`` makes (and, for ``bench`` and ``datasets``, the
benchmark graphs that ``datasets download`` fetches, here from a local mirror)."""

from __future__ import annotations

import contextlib
import io
import shlex

import pytest
from posegraph_cli.examples import EXAMPLES
from posegraph_cli.main import main
from posegraph_datasets.paths import shared_datasets_dir

NEEDS_BENCHMARK_GRAPHS = {"bench", "datasets"}


def _commands(command: str) -> list[list[str]]:
    """The example lines of ``command``'s help, as argument lists (comments dropped)."""
    lines = EXAMPLES[command].splitlines()[1:]
    return [shlex.split(line, comments=True)[1:] for line in lines]


@pytest.mark.parametrize("command", sorted(EXAMPLES))
def test_every_help_example_runs(command, tmp_path, monkeypatch):
    if command in NEEDS_BENCHMARK_GRAPHS:
        mirror = shared_datasets_dir()
        if mirror is None:
            pytest.skip("needs ../shared/datasets as the mirror that datasets download reads")
        monkeypatch.setenv("POSEGRAPH_DATASETS_URL", mirror.as_uri())
    monkeypatch.setenv("POSEGRAPH_DATASETS", str(tmp_path / "downloaded"))
    monkeypatch.setenv("POSEGRAPH_SHARED_DATASETS", str(tmp_path / "no_shared_datasets"))
    monkeypatch.chdir(tmp_path)
    for arguments in _commands(command):
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(arguments) == 0, arguments
    assert len(list(tmp_path.iterdir())) >= 1


def test_every_command_has_examples_that_start_with_its_name():
    for command, text in EXAMPLES.items():
        assert text.startswith("examples:\n"), command
        assert any(arguments[0] == command for arguments in _commands(command)), command
