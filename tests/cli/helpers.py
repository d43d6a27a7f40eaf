"""How the command-line tests run the posegraph command, and the examples they run it on."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from posegraph_cli.schema import SCHEMAS
from posegraph_datasets import example
from posegraph_datasets.monocular import monocular_sequence, write_sequence
from posegraph_datasets.outliers import add_false_loops

from posegraph.io import write_graph

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


def not_json(constant: str):
    raise ValueError(f"{constant} is not JSON")


def run_json(command: str, *args, check_exit: int | None = 0):
    completed = run(command, *args, "--json", check_exit=check_exit)
    document = json.loads(completed.stdout, parse_constant=not_json)  # no NaN or Infinity
    jsonschema.validate(document, SCHEMAS[command])
    return document


def assert_not_blank(png) -> None:
    import matplotlib.image

    pixels = matplotlib.image.imread(str(png))[..., :3]
    assert pixels.var() > 1e-3
    assert (pixels.min(axis=2) < 0.9).mean() > 0.005  # more than 0.5% of the pixels are drawn


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
