"""Marginal covariances of chosen poses against gtsam.Marginals, side by side.

Usage: ``python -m posegraph.benchmarks.marginals [--nodes 1 100 1000 0] [--graph G]``.
The graph (by default the shared sphere2500.g2o, else gtsam's Data/sphere2500.txt) is optimised
once; then, for each count (0: every pose but the gauge), ``posegraph.marginals`` for that many
random poses, and gtsam's ``Marginals`` (its construction, which factorises, plus one
``marginalCovariance`` per pose) at the same values. Prints both times (best of ``repeats``)
and the largest relative difference of the blocks.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..api import optimize
from ..graph import PoseGraph
from ..io import read_graph
from ..marginals import marginals
from .timing import at_least, best_time


def default_graph() -> Path | None:
    shared, data = shared_datasets_dir(), gtsam_data_dir()
    if shared is not None and (shared / "sphere2500.g2o").is_file():
        return shared / "sphere2500.g2o"
    return None if data is None else data / "sphere2500.txt"


def run(path: Path, counts: list[int], repeats: int) -> str:
    graph = read_graph(str(path)).graph
    optimize(graph)
    lines = [f"{path.name}: marginal covariances, posegraph against gtsam"]
    for count in counts:
        chosen = graph.num_nodes - 1 if count == 0 else min(count, graph.num_nodes - 1)
        lines.append(_compare(graph, chosen, repeats))
    return "\n".join(lines)


def _compare(graph: PoseGraph, count: int, repeats: int) -> str:
    import gtsam

    from ..validation.gtsam_bridge import graph_to_gtsam, matrix_from_gtsam

    nodes = np.random.default_rng(0).choice(graph.node_ids[1:], count, replace=False)
    ours = marginals(graph, nodes)
    factors, values = graph_to_gtsam(graph)

    def with_gtsam() -> list[np.ndarray]:
        computed = gtsam.Marginals(factors, values)
        return [computed.marginalCovariance(int(k)) for k in nodes]

    theirs = np.stack([matrix_from_gtsam(graph.group, m) for m in with_gtsam()])
    scale = np.abs(theirs).max(axis=(1, 2), keepdims=True)
    difference = float((np.abs(ours - theirs) / scale).max())
    our_time = best_time(lambda: marginals(graph, nodes), repeats)
    their_time = best_time(with_gtsam, repeats)
    return (
        f"  {count} of {graph.num_nodes} poses: posegraph {our_time:.3f} s, "
        f"gtsam {their_time:.3f} s, ratio {our_time / their_time:.2f}; largest difference "
        f"relative to each block's largest entry {difference:.1e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[1, 100, 1000, 0])
    parser.add_argument("--repeats", type=at_least(1), default=3)
    parser.add_argument("--graph", help="a graph file (default: sphere2500)")
    args = parser.parse_args()
    path = Path(args.graph) if args.graph else default_graph()
    if path is None:
        raise SystemExit("no graph given, and neither ../shared/datasets nor gtsam's Data/ found")
    print(run(path, args.nodes, args.repeats))


if __name__ == "__main__":
    main()
