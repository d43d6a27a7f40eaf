"""Certification of the benchmark graphs against SE-Sync's published results.

Usage: ``python -m posegraph.benchmarks.certify [--graphs intel sphere2500 ...]``.
For each SE2 and SE3 graph of ``../shared/datasets`` (and gtsam's w10000 and sphere2500.txt),
posegraph optimises it (defaults), then ``posegraph.certify`` checks the result on SE-Sync's
isotropic problem. The table gives both times, the certified SE-Sync objective beside the
value SE-Sync's paper lists (Rosen et al., IJRR 2019, Tables 2 and 3), λ_min(S) and the
verdict, and posegraph's own error at its optimum and after its Levenberg-Marquardt from the
certified estimate.
"""

from __future__ import annotations

import argparse
import time

from posegraph_datasets.paths import benchmark_graph, gtsam_data_dir

from ..api import optimize
from ..certification import certify
from ..io import ReadOptions, read_graph
from .table import MarkdownTable

PUBLISHED = {
    "sphere2500.g2o": 1.687e3,
    "torus3D.g2o": 2.423e4,
    "parking-garage.g2o": 1.263,
    "cubicle.g2o": 7.171e2,
    "CSAIL.g2o": 3.170e1,
    "intel.g2o": 5.235e1,
    "MIT.g2o": 6.115e1,
    "manhattan.g2o": 6.432e3,
}
"""f* of SE-Sync's paper (4 significant digits) for the datasets it lists."""
ISOTROPIC = {"cubicle.g2o"}
"""Graphs read with ``repair_information="isotropic"``: cubicle's information matrices are not
positive semi-definite, and SE-Sync uses only their isotropic part."""
GRAPHS = [
    "CSAIL.g2o", "intel.g2o", "MIT.g2o", "manhattan.g2o", "tinyGrid3D.g2o", "smallGrid3D.g2o",
    "sphere2500.g2o", "torus3D.g2o", "parking-garage.g2o", "sphere_bignoise_vertex3.g2o",
    "cubicle.g2o", "w10000.graph", "sphere2500.txt",
]  # fmt: skip


def row(name: str) -> str | None:
    """One table row, or None where the graph is not on this machine."""
    path = benchmark_graph(name)
    if path is None and gtsam_data_dir() is not None:
        candidate = gtsam_data_dir() / name
        path = candidate if candidate.is_file() else None
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
    published = PUBLISHED.get(name)
    cells = [
        name,
        f"{optimisation:.2f} s",
        f"{certificate.time:.2f} s",
        f"{certificate.time / optimisation:.1f}",
        f"{certificate.objective:.6g}",
        "–" if published is None else f"{published:.4g}",
        f"{certificate.smallest_eigenvalue:.1e}",
        "certified" if certificate.certified else "not certified",
        str(certificate.rank),
        f"{error:.6g} / {after:.6g}",
    ]
    return " | ".join(cells)


def main(arguments: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="+", default=GRAPHS, help="file names")
    args = parser.parse_args(arguments)
    table = MarkdownTable(
        "graph | posegraph optimise | certify | ratio | SE-Sync objective | published | "
        "λ_min(S) | verdict | highest rank | posegraph's error: own / from certified",
        echo=True,
    )
    table.add_present(row(name) for name in args.graphs)


if __name__ == "__main__":
    main()
