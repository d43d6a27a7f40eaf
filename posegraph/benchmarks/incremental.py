"""Streaming a graph into a back end: warm starts against optimising every prefix from scratch.

Usage: ``python -m posegraph.benchmarks.incremental [--step 100] [--graph w10000.graph]
[--robust gnc --false-loops 0.1 --seed 0]``.
The graph (by default gtsam's Data/w10000.graph) arrives ``step`` poses at a time: the new
poses come without values, with every edge whose two ends have arrived, and
``posegraph.optimize`` runs after each step (warm start). The reference optimises each prefix as
a new graph (its default initialisation). Times count the ``optimize`` calls only. With
``--robust``, every call is robust, and ``--false-loops`` first adds that share of seeded false
loop closures (``posegraph_datasets.outliers``); the last calls' rejection rates are reported.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from posegraph_datasets.outliers import add_false_loops, rejection_rates
from posegraph_datasets.paths import gtsam_data_dir

from ..api import RESTART, optimize
from ..graph import PoseGraph
from ..io import read_graph
from ..solvers import Summary
from .timing import at_least


def arrivals(full: PoseGraph, step: int) -> tuple[np.ndarray, np.ndarray]:
    """The node ids in the order they arrive (ascending), and the step at which each edge
    arrives: the step of its later end."""
    ids = np.sort(full.node_ids)
    edge_ready = np.maximum(
        np.searchsorted(ids, full.node_ids[full.edges.i]),
        np.searchsorted(ids, full.node_ids[full.edges.j]),
    )
    return ids, edge_ready // step


def stream(full: PoseGraph, step: int):
    """Yield the growing graph after each step (the same object, grown in place). Its edges
    are ``full``'s in the order ``np.argsort(arrivals(full, step)[1], kind="stable")``."""
    ids, edge_steps = arrivals(full, step)
    graph = PoseGraph(full.group)
    for k, start in enumerate(range(0, ids.size, step)):
        new = ids[start : start + step]
        if start == 0:
            graph.add_nodes(new[:1], full.values_of(new[:1]))
            graph.add_nodes(new[1:])
        else:
            graph.add_nodes(new)
        edges = np.flatnonzero(edge_steps == k)
        e = full.edges
        graph.add_edges(
            full.node_ids[e.i[edges]],
            full.node_ids[e.j[edges]],
            e.measurements[edges],
            e.information[edges],
        )
        yield graph


def run(
    path: Path, step: int, robust: str | None = None, false_loops: float = 0.0, seed: int = 0
) -> str:
    full = read_graph(str(path)).graph
    false = np.zeros(full.num_edges, dtype=bool)
    if false_loops:
        full, false = add_false_loops(full, false_loops, seed)
    warm_total, scratch_total, rows = 0.0, 0.0, []
    for graph in stream(full, step):
        start = time.perf_counter()
        warm = optimize(graph, robust=robust)
        warm_total += time.perf_counter() - start
        prefix = graph.copy()
        prefix.solution = None
        prefix.set_values(prefix.values)
        start = time.perf_counter()
        scratch = optimize(prefix, robust=robust)
        scratch_total += time.perf_counter() - start
        rows.append((graph.num_nodes, warm.summary, scratch.summary))
    last_warm, last_scratch = rows[-1][1], rows[-1][2]
    difference = (last_warm.final_error - last_scratch.final_error) / last_scratch.final_error
    iterations = np.mean([w.num_iterations for _, w, _ in rows])
    scratch_iterations = np.mean([s.num_iterations for _, _, s in rows])
    restarts = sum(w.initialization == RESTART for _, w, _ in rows[1:])
    lines = [
        f"{path.name}: {full.num_nodes} poses streamed in steps of {step} ({len(rows)} optimisations)",
        f"  warm starts:   total {warm_total:.2f} s, {iterations:.1f} iterations per call on average,"
        f" {restarts} of {len(rows) - 1} restarted from chordal (new measurements disagreed)",
        f"  from scratch:  total {scratch_total:.2f} s, {scratch_iterations:.1f} iterations per call"
        f" (the last, on the whole graph: {last_scratch.total_time:.2f} s)",
        f"  ratio warm / scratch: {warm_total / scratch_total:.3f}",
        f"  final error: warm {last_warm.final_error:.10g}, scratch {last_scratch.final_error:.10g}"
        f" (relative difference {difference:+.1e})",
        f"  last call reused: {', '.join(last_warm.reused) or 'nothing'}",
    ]
    if robust is not None:
        streamed_false = false[np.argsort(arrivals(full, step)[1], kind="stable")]
        lines.append(
            f"  robust {last_warm.robust}, {false.sum()} false loops (seed {seed}): the last calls"
            f" reject {_rates(graph, streamed_false, last_warm)} (warm),"
            f" {_rates(graph, streamed_false, last_scratch)} (scratch)"
        )
    return "\n".join(lines)


def _rates(graph: PoseGraph, false: np.ndarray, summary: Summary) -> str:
    false_rejected, true_rejected = rejection_rates(graph, false, summary.rejected_edges)
    return f"{false_rejected:.1%} of the false loops and {true_rejected:.2%} of the true ones"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=at_least(1), default=100)
    parser.add_argument("--graph", help="a graph file (default: gtsam's Data/w10000.graph)")
    parser.add_argument("--robust", help="a robust spec for every call, as optimize's (gnc, …)")
    parser.add_argument(
        "--false-loops", type=float, default=0.0, help="share of false loop closures to add"
    )
    parser.add_argument("--seed", type=int, default=0, help="of the false loops")
    args = parser.parse_args()
    if args.graph:
        path = Path(args.graph)
    elif gtsam_data_dir() is not None:
        path = gtsam_data_dir() / "w10000.graph"
    else:
        raise SystemExit("no graph given and gtsam's Data/ is not installed")
    print(run(path, args.step, args.robust, args.false_loops, args.seed))


if __name__ == "__main__":
    main()
