"""Marginal covariances of chosen poses, and of relative poses, against gtsam.Marginals, side by side.

Usage: ``python -m posegraph.benchmarks.marginals [--nodes 1 100 1000 0] [--pairs 10 100]
[--random-pairs 100] [--graph G]``. The graph (by default the shared sphere2500.g2o, else
gtsam's Data/sphere2500.txt) is optimised once; then, for each count of ``--nodes`` (0: every
pose but the gauge), ``posegraph.analysis.marginals`` for that many random poses, and gtsam's
``Marginals`` (its construction, which factorises, plus one ``marginalCovariance`` per pose) at
the same values. For each count of ``--pairs`` (a loop-closure search: the newest pose against
that many others) and of ``--random-pairs``, ``posegraph.relative_covariances`` of the pairs,
and gtsam's ``Marginals`` with one ``jointMarginalCovariance`` per pair, mapped through the
Jacobians of gtsam's ``between``. Prints both times (best of ``repeats``) and the largest
relative difference of the blocks.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..analysis.marginals import marginals, relative_covariances
from ..api import optimize
from ..graph import PoseGraph
from ..io import load_graph
from .timing import at_least, best_time


def default_graph() -> Path | None:
    shared, data = shared_datasets_dir(), gtsam_data_dir()
    if shared is not None and (shared / "sphere2500.g2o").is_file():
        return shared / "sphere2500.g2o"
    return None if data is None else data / "sphere2500.txt"


def run(
    path: Path,
    counts: list[int],
    pair_counts: list[int],
    random_pair_counts: list[int],
    repeats: int,
) -> str:
    graph = load_graph(str(path)).graph
    optimize(graph)
    lines = [f"{path.name}: covariances, posegraph against gtsam"]
    for count in counts:
        chosen = graph.num_nodes - 1 if count == 0 else min(count, graph.num_nodes - 1)
        lines.append(_compare_nodes(graph, chosen, repeats))
    rng = np.random.default_rng(1)
    newest, others = graph.node_ids[-1], graph.node_ids[1:-1]
    for count in pair_counts:
        chosen = rng.choice(others, min(count, others.size), replace=False)
        pairs = np.stack([np.full(chosen.size, newest), chosen], axis=1)
        lines.append(
            _compare_pairs(graph, pairs, f"the newest pose and {chosen.size} others", repeats)
        )
    for count in random_pair_counts:
        pairs = rng.choice(graph.node_ids[1:], (count, 2), replace=2 * count >= graph.num_nodes)
        lines.append(_compare_pairs(graph, pairs, f"{count} random pairs", repeats))
    return "\n".join(lines)


def _compare_nodes(graph: PoseGraph, count: int, repeats: int) -> str:
    import gtsam

    from ..lie.gtsam_order import matrix_from_gtsam
    from ..validation.gtsam_bridge import graph_to_gtsam

    nodes = np.random.default_rng(0).choice(graph.node_ids[1:], count, replace=False)
    factors, values = graph_to_gtsam(graph)

    def with_gtsam() -> list[np.ndarray]:
        computed = gtsam.Marginals(factors, values)
        return [matrix_from_gtsam(graph.group, computed.marginalCovariance(k)) for k in nodes]

    label = f"{count} of {graph.num_nodes} poses"
    return _line(label, lambda: marginals(graph, nodes), with_gtsam, repeats)


def _compare_pairs(graph: PoseGraph, pairs: np.ndarray, label: str, repeats: int) -> str:
    """Relative covariances of the node ``pairs`` (k, 2) (ids)."""
    import gtsam

    from ..lie.gtsam_order import matrix_from_gtsam
    from ..validation.gtsam_bridge import graph_to_gtsam, to_gtsam

    factors, values = graph_to_gtsam(graph)
    poses = {int(k): to_gtsam(graph.values_of([k])[0]) for k in np.unique(pairs)}
    d = graph.group.dof

    def with_gtsam() -> list[np.ndarray]:
        computed = gtsam.Marginals(factors, values)
        relative = []
        for a, b in pairs.tolist():
            joint = computed.jointMarginalCovariance([a, b])
            covariance = np.block(
                [[joint.at(a, a), joint.at(a, b)], [joint.at(b, a), joint.at(b, b)]]
            )
            h_a, h_b = np.zeros((d, d), order="F"), np.zeros((d, d), order="F")
            poses[a].between(poses[b], h_a, h_b)
            jacobian = np.hstack([h_a, h_b])
            relative.append(matrix_from_gtsam(graph.group, jacobian @ covariance @ jacobian.T))
        return relative

    label = f"relative poses of {label}"
    return _line(
        label, lambda: relative_covariances(graph, pairs[:, 0], pairs[:, 1]), with_gtsam, repeats
    )


def _line(label: str, ours, theirs, repeats: int) -> str:
    """One row: both computations' best times and their largest difference, relative to each
    block's largest entry."""
    our_blocks, their_blocks = ours(), np.stack(theirs())
    scale = np.abs(their_blocks).max(axis=(1, 2), keepdims=True)
    difference = float((np.abs(our_blocks - their_blocks) / scale).max())
    our_time, their_time = best_time(ours, repeats), best_time(theirs, repeats)
    return (
        f"  {label}: posegraph {our_time:.3f} s, gtsam {their_time:.3f} s, ratio "
        f"{our_time / their_time:.2g}; largest difference relative to each block's largest "
        f"entry {difference:.1e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, nargs="*", default=[1, 100, 1000, 0])
    parser.add_argument("--pairs", type=int, nargs="*", default=[10, 100])
    parser.add_argument("--random-pairs", type=int, nargs="*", default=[100])
    parser.add_argument("--repeats", type=at_least(1), default=3)
    parser.add_argument("--graph", help="a graph file (default: sphere2500)")
    args = parser.parse_args()
    path = Path(args.graph) if args.graph else default_graph()
    if path is None:
        raise SystemExit("no graph given, and neither ../shared/datasets nor gtsam's Data/ found")
    print(run(path, args.nodes, args.pairs, args.random_pairs, args.repeats))


if __name__ == "__main__":
    main()
