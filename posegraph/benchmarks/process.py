"""Whole processes side by side: ``posegraph optimize FILE`` against a Python script that reads
the same file with gtsam and runs its Levenberg-Marquardt (the first pose held), start-up and
reading included.

Usage: ``python -m posegraph.benchmarks.process [--graphs sphere2500.g2o w10000.graph]
[--runs 5]``. The processes take turns, ``--runs`` of each (after one untimed run of each that
leaves the bytecode compiled, as an installed package has it); the table gives the medians,
their ratio, and the best runs. posegraph runs quiet (``-q``, nothing shown, so its noise check
is skipped) and with its summary.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from posegraph_datasets.paths import benchmark_or_gtsam_graph

from ..io.tags import G2O_TAGS, TORO_TAGS
from ..lie import SE3
from .table import MarkdownTable
from .timing import at_least

GTSAM_SCRIPT = """
import sys
import gtsam
path, dimension = sys.argv[1], int(sys.argv[2])
if path.endswith(".graph"):
    graph, values = gtsam.load2D(path)
else:
    graph, values = gtsam.readG2o(path, dimension == 3)
first = min(values.keys())
if dimension == 3:
    graph.add(gtsam.PriorFactorPose3(first, values.atPose3(first), gtsam.noiseModel.Constrained.All(6)))
else:
    graph.add(gtsam.PriorFactorPose2(first, values.atPose2(first), gtsam.noiseModel.Constrained.All(3)))
result = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams()).optimize()
print(graph.error(result))
"""
"""The peer: gtsam's reader (``load2D`` for TORO's ``.graph``) and Levenberg-Marquardt with
default parameters, the first pose held by a constrained prior."""

POSEGRAPH = "from posegraph_cli.main import main; main()"


def dimension(path: Path) -> int:
    """2 or 3, from the group of the file's first vertex or edge line (the reader's tags)."""
    tags = {**G2O_TAGS, **TORO_TAGS}
    with open(path) as lines:
        for words in map(str.split, lines):
            tag = tags.get(words[0]) if words else None
            if tag is not None and tag.kind in ("vertex", "edge"):
                return 3 if tag.group is SE3 else 2
    raise ValueError(f"{path}: no vertex or edge line")


def commands(path: Path) -> dict[str, list[str]]:
    """The timed processes, by name."""
    python = sys.executable
    optimize = [python, "-c", POSEGRAPH, "optimize", str(path)]
    return {
        "gtsam": [python, "-c", GTSAM_SCRIPT, str(path), str(dimension(path))],
        "posegraph -q": [*optimize, "-q"],
        "posegraph": optimize,
    }


def run(command: list[str]) -> float:
    """Wall-clock seconds of one process; its output is discarded (its errors shown, should it
    fail)."""
    environment = dict(os.environ)
    environment.pop("PYTHONDONTWRITEBYTECODE", None)  # an installed package's bytecode is cached
    began = time.perf_counter()
    finished = subprocess.run(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=environment
    )
    elapsed = time.perf_counter() - began
    if finished.returncode != 0:
        raise RuntimeError(f"{' '.join(command[2:])} failed:\n{finished.stderr}")
    return elapsed


def row(name: str, runs: int) -> str | None:
    """One table row; None where the graph is not on this machine."""
    path = benchmark_or_gtsam_graph(name)
    if path is None:
        return None
    timed = commands(path)
    for command in timed.values():
        run(command)
    times: dict[str, list[float]] = {label: [] for label in timed}
    for _ in range(runs):
        for label, command in timed.items():
            times[label].append(run(command))
    median = {label: statistics.median(seconds) for label, seconds in times.items()}
    best = {label: min(seconds) for label, seconds in times.items()}
    return (
        f"{name} | {median['gtsam']:.2f} s | {median['posegraph -q']:.2f} s"
        f" | {median['posegraph -q'] / median['gtsam']:.2f} | {median['posegraph']:.2f} s"
        f" | {median['posegraph'] / median['gtsam']:.2f}"
        f" | {best['gtsam']:.2f} / {best['posegraph -q']:.2f} / {best['posegraph']:.2f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--graphs", nargs="+", default=["sphere2500.g2o", "w10000.graph"])
    parser.add_argument("--runs", type=at_least(1), default=5, help="timed runs of each")
    args = parser.parse_args()
    table = MarkdownTable(
        "graph | gtsam script | posegraph -q | ratio | posegraph (summary) | ratio"
        " | best runs (gtsam / -q / summary)",
        echo=True,
    )
    table.add_present(row(name, args.runs) for name in args.graphs)


if __name__ == "__main__":
    main()
