"""The docs site builds with ``mkdocs build --strict``, its API reference lists every public
name, and the tutorials' commands run as written, in order, in an empty folder."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from posegraph_cli.main import main

import posegraph

ROOT = Path(__file__).resolve().parent.parent
TUTORIALS = sorted((ROOT / "docs").glob("tutorial-*.md"))


def test_the_site_builds_strictly_and_its_api_reference_lists_every_public_name(tmp_path):
    pytest.importorskip("mkdocs")
    site = tmp_path / "site"
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin"},
        timeout=300,
    )
    assert built.returncode == 0, built.stderr
    reference = (site / "api" / "index.html").read_text()
    missing = [name for name in posegraph.__all__ if f'id="posegraph.{name}"' not in reference]
    assert not missing
    guide = (site / "index.html").read_text()
    assert "A five-minute tour" in guide and 'href="benchmarks/' in guide
    for tutorial in TUTORIALS:
        assert (site / tutorial.stem / "index.html").is_file()
    figures = (site / "tutorial-command-line" / "index.html").read_text()
    for figure in ("eval.png", "ellipses.png", "html-view.png"):
        assert f'src="../figures/{figure}"' in figures and (site / "figures" / figure).is_file()


@pytest.mark.parametrize("tutorial", TUTORIALS, ids=[t.stem for t in TUTORIALS])
def test_tutorial_commands_run_in_order(tutorial, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```bash\n(.*?)```", tutorial.read_text(), flags=re.S)
    commands = [shlex.split(line)[1:] for block in blocks for line in block.splitlines()]
    for arguments in commands:
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(arguments) == 0, arguments
