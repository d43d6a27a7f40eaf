"""Everything the README and docs/ show runs: their Python examples, the README's tour of the
command line, its main-job command, and every benchmark command that docs/ names."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
DOCS = {path.name: path.read_text() for path in sorted((ROOT / "docs").glob("*.md"))}
PAGES = {"README.md": README, **DOCS}
PYTHON_BLOCKS = [
    (name, code)
    for name, text in PAGES.items()
    for code in re.findall(r"```python\n(.*?)```", text, flags=re.S)
]
TOUR = [
    line
    for block in re.findall(r"```bash\n(.*?)```", README, flags=re.S)
    for line in block.splitlines()
    if line.startswith(("posegraph ", "python -m posegraph_datasets"))
]
BENCHMARK_COMMANDS = sorted(
    {
        line.split("#")[0].split()[2]
        for text in DOCS.values()
        for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S)
        for line in block.splitlines()
        if line.startswith("python -m posegraph.benchmarks.")
    }
)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A fresh folder with the bundled ``datasets/`` reachable as in a checkout."""
    (tmp_path / "datasets").symlink_to(ROOT / "datasets")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_readme_has_examples():
    assert sum(name == "README.md" for name, _ in PYTHON_BLOCKS) >= 4
    assert len(TOUR) >= 5 and len(BENCHMARK_COMMANDS) >= 8


@pytest.mark.parametrize(
    "code",
    [code for _, code in PYTHON_BLOCKS],
    ids=[f"{name}-block{k}" for k, (name, _) in enumerate(PYTHON_BLOCKS)],
)
def test_python_example_runs(workdir, code):
    completed = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert completed.returncode == 0, completed.stderr


def _command(line: str) -> list[str]:
    """A line of the README as the command it runs: ``posegraph`` as installed, ``python`` as
    this interpreter."""
    words = shlex.split(line.split(" #")[0])
    if words[0] == "python":
        return [sys.executable, *words[1:]]
    executable = shutil.which("posegraph")
    if executable is None:
        pytest.skip("the posegraph command is not installed (pip install -e .)")
    return [executable, *words[1:]]


def test_the_tour_runs_in_order(workdir):
    """Each command of the tour, in a fresh folder, succeeds and writes what it names."""
    for line in TOUR:
        completed = subprocess.run(_command(line), capture_output=True, text=True, timeout=300)
        assert completed.returncode == 0, (line, completed.stderr)
    for written in ("manhattan.g2o", "manhattan.png", "covariances.txt", "corrected.tum"):
        assert (workdir / written).stat().st_size > 0, written


@pytest.mark.parametrize("module", BENCHMARK_COMMANDS)
def test_every_benchmark_command_that_docs_name_exists(module):
    """A benchmark takes minutes: its command is checked by its ``--help``."""
    completed = subprocess.run(
        [sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=120
    )
    assert completed.returncode == 0 and "usage" in completed.stdout, completed.stderr


def test_main_job_command_runs(workdir):
    """The first set-up command's job (its install step is what the test environment is)."""
    command = re.search(r"&& (posegraph optimize [^\n]+)", README).group(1)
    completed = subprocess.run(_command(command), capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert (workdir / "sphere_optimised.g2o").is_file() and (
        workdir / "sphere_optimised.png"
    ).is_file()
    assert "termination" in completed.stdout


def test_test_command_is_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text()
    command = "python -m pip install -e '.[test]' && python -m pytest -n auto"
    assert command in README
    assert "pip install" in ci and "-e '.[test]'" in ci and "pytest -q -n auto" in ci
    assert os.access(ROOT / ".ci" / "run", os.X_OK)
