"""Certification of the benchmark graphs, beside SE-Sync's own executable.

Usage: ``python -m posegraph.benchmarks.certify [--graphs intel.g2o ...] [--sesync PATH]``.
For each SE2 and SE3 graph of ``../shared/datasets`` (and gtsam's w10000 and sphere2500.txt),
posegraph optimises it (defaults), then ``posegraph.certify`` checks the result on SE-Sync's
isotropic problem. The table gives both times, the certified SE-Sync objective, λ_min(S) and
the verdict, and posegraph's own error at its optimum and after its Levenberg-Marquardt from
the certified estimate. With ``--sesync``, the ``SE-Sync`` executable built from its public
repository (david-m-rosen/SE-Sync, C++; not part of posegraph) runs on the same file, which it
reads itself (g2o files only): its F(x) and total time, and posegraph's optimisation and
certification over that time.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import time
from pathlib import Path

from posegraph_datasets.paths import benchmark_or_gtsam_graph

from ..api import optimize
from ..certification import certify
from ..io import ReadOptions, read_graph
from .table import MarkdownTable

SESYNC_PATTERNS = {
    "objective": r"Value of rounded pose estimates F\(x\): (\S+)",
    "seconds": r"Total elapsed computation time: (\S+) seconds",
}
"""What the SE-Sync executable prints of its result (the last match of each)."""
ISOTROPIC = {"cubicle.g2o"}
"""Graphs read with ``repair_information="isotropic"``: cubicle's information matrices are not
positive semi-definite, and SE-Sync uses only their isotropic part."""
GRAPHS = [
    "CSAIL.g2o", "intel.g2o", "MIT.g2o", "manhattan.g2o", "tinyGrid3D.g2o", "smallGrid3D.g2o",
    "sphere2500.g2o", "torus3D.g2o", "parking-garage.g2o", "sphere_bignoise_vertex3.g2o",
    "cubicle.g2o", "w10000.graph", "sphere2500.txt",
]  # fmt: skip


def sesync_result(executable: str, path: Path) -> tuple[float, float] | None:
    """(F(x), total seconds) that the SE-Sync executable prints for ``path``; None for a file
    that is not g2o, which it cannot read."""
    with open(path) as lines:
        if not lines.readline().startswith(("VERTEX_SE", "EDGE_SE")):
            return None
    printed = subprocess.run(
        [executable, str(path)], capture_output=True, text=True, check=True
    ).stdout
    objective, seconds = (
        float(re.findall(pattern, printed)[-1]) for pattern in SESYNC_PATTERNS.values()
    )
    return objective, seconds


def row(name: str, sesync: str | None = None) -> str | None:
    """One table row, or None where the graph is not on this machine."""
    path = benchmark_or_gtsam_graph(name)
    if path is None:
        return None
    repair = "isotropic" if name in ISOTROPIC else None  # SE-Sync's model of its information
    graph = read_graph(path, ReadOptions(repair_information=repair)).graph
    began = time.perf_counter()
    error = optimize(graph).summary.final_error
    optimisation = time.perf_counter() - began
    certificate = certify(graph)
    refined = graph.copy()
    refined.set_values(certificate.values)
    after = optimize(refined, init="file").summary.final_error
    cells = [
        name,
        f"{optimisation:.2f} s",
        f"{certificate.time:.2f} s",
        f"{certificate.time / optimisation:.1f}",
        f"{certificate.objective:.6g}",
        f"{certificate.smallest_eigenvalue:.1e}",
        "certified" if certificate.certified else "not certified",
        str(certificate.rank),
        f"{error:.6g} / {after:.6g}",
    ]
    theirs = None if sesync is None else sesync_result(sesync, path)
    if theirs is not None:
        ratio = (optimisation + certificate.time) / theirs[1]
        cells += [f"{theirs[0]:.6g}", f"{theirs[1]:.2f} s", f"{ratio:.2f}"]
    elif sesync is not None:
        cells += ["–", "–", "–"]
    return " | ".join(cells)


def main(arguments: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="+", default=GRAPHS, help="file names")
    parser.add_argument("--sesync", help="an SE-Sync executable, run on the same files")
    args = parser.parse_args(arguments)
    header = (
        "graph | posegraph optimise | certify | ratio | SE-Sync objective | λ_min(S) | verdict"
        " | highest rank | posegraph's error: own / from certified"
    )
    if args.sesync:
        header += " | SE-Sync executable F(x) | its time | posegraph (both) / SE-Sync"
    table = MarkdownTable(header, echo=True)
    table.add_present(row(name, args.sesync) for name in args.graphs)


if __name__ == "__main__":
    main()
