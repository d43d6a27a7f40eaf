"""Everything the README shows runs: its Python examples and its main-job command."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
PYTHON_BLOCKS = re.findall(r"```python\n(.*?)```", README, flags=re.S)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A fresh folder with the bundled ``datasets/`` reachable as in a checkout."""
    (tmp_path / "datasets").symlink_to(ROOT / "datasets")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_readme_has_examples():
    assert len(PYTHON_BLOCKS) >= 3


@pytest.mark.parametrize(
    "code", PYTHON_BLOCKS, ids=[f"block{k}" for k in range(len(PYTHON_BLOCKS))]
)
def test_python_example_runs(workdir, code):
    completed = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr


def test_main_job_command_runs(workdir):
    """The first set-up command's job (its install step is what the test environment is)."""
    command = re.search(r"&& (posegraph optimize [^\n]+)", README).group(1).split()
    executable = shutil.which("posegraph")
    if executable is None:
        pytest.skip("the posegraph command is not installed (pip install -e .)")
    completed = subprocess.run(
        [executable, *command[1:]], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr
    assert (workdir / "sphere_optimised.g2o").is_file() and (
        workdir / "sphere_optimised.png"
    ).is_file()
    assert "termination" in completed.stdout


def test_test_command_is_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text()
    assert "python -m pip install -e '.[test]'" in README and "python -m pytest" in README
    assert "pip install" in ci and "-e '.[test]'" in ci and "pytest" in ci
    assert os.access(ROOT / ".ci" / "run", os.X_OK)
