"""Streaming a graph into a back end: warm starts against optimising every prefix from scratch.

Usage: ``python -m posegraph.benchmarks.incremental [--step 100] [--graph w10000.graph]``.
The graph (by default gtsam's Data/w10000.graph) arrives ``step`` poses at a time: the new
poses come without values, with every edge whose two ends have arrived, and
``posegraph.optimize`` runs after each step (warm start). The reference optimises each prefix as
a new graph (its default initialisation). Times count the ``optimize`` calls only.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from posegraph_datasets.paths import gtsam_data_dir

from ..api import RESTART, optimize
from ..graph import PoseGraph
from ..io import read_graph


def stream(full: PoseGraph, step: int):
    """Yield the growing graph after each step (the same object, grown in place)."""
    order = np.argsort(full.node_ids)
    ids = full.node_ids[order]
    edge_ready = np.maximum(
        np.searchsorted(ids, full.node_ids[full.edges.i]),
        np.searchsorted(ids, full.node_ids[full.edges.j]),
    )
    graph = PoseGraph(full.group)
    for start in range(0, ids.size, step):
        new = ids[start : start + step]
        if start == 0:
            graph.add_nodes(new[:1], full.values_of(new[:1]))
            graph.add_nodes(new[1:])
        else:
            graph.add_nodes(new)
        edges = np.flatnonzero((edge_ready >= start) & (edge_ready < start + step))
        e = full.edges
        graph.add_edges(
            full.node_ids[e.i[edges]],
            full.node_ids[e.j[edges]],
            e.measurements[edges],
            e.information[edges],
        )
        yield graph


def run(path: Path, step: int) -> str:
    full = read_graph(str(path)).graph
    warm_total, scratch_total, rows = 0.0, 0.0, []
    for graph in stream(full, step):
        start = time.perf_counter()
        warm = optimize(graph)
        warm_total += time.perf_counter() - start
        prefix = graph.copy()
        prefix.solution = None
        prefix.set_values(prefix.values)
        start = time.perf_counter()
        scratch = optimize(prefix)
        scratch_total += time.perf_counter() - start
        rows.append((graph.num_nodes, warm.summary, scratch.summary))
    last_warm, last_scratch = rows[-1][1], rows[-1][2]
    difference = (last_warm.final_error - last_scratch.final_error) / last_scratch.final_error
    iterations = np.mean([w.num_iterations for _, w, _ in rows])
    scratch_iterations = np.mean([s.num_iterations for _, _, s in rows])
    restarts = sum(w.initialization == RESTART for _, w, _ in rows[1:])
    return "\n".join(
        [
            f"{path.name}: {full.num_nodes} poses streamed in steps of {step} ({len(rows)} optimisations)",
            f"  warm starts:   total {warm_total:.2f} s, {iterations:.1f} iterations per call on average,"
            f" {restarts} of {len(rows) - 1} restarted from chordal (new measurements disagreed)",
            f"  from scratch:  total {scratch_total:.2f} s, {scratch_iterations:.1f} iterations per call",
            f"  ratio warm / scratch: {warm_total / scratch_total:.3f}",
            f"  final error: warm {last_warm.final_error:.10g}, scratch {last_scratch.final_error:.10g}"
            f" (relative difference {difference:+.1e})",
            f"  last call reused: {', '.join(last_warm.reused) or 'nothing'}",
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=int, default=100)
    parser.add_argument("--graph", help="a graph file (default: gtsam's Data/w10000.graph)")
    args = parser.parse_args()
    if args.graph:
        path = Path(args.graph)
    elif gtsam_data_dir() is not None:
        path = gtsam_data_dir() / "w10000.graph"
    else:
        raise SystemExit("no graph given and gtsam's Data/ is not installed")
    print(run(path, args.step))


if __name__ == "__main__":
    main()
