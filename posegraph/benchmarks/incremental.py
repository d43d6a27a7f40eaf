"""Streaming a graph into a back end: warm starts against optimising every prefix from scratch.

Usage: ``python -m posegraph.benchmarks.incremental [--step 100] [--graph w10000.graph]
[--robust gnc --false-loops 0.1 --seed 0] [--gtsam | --isam2 [--skip-within 0.01]]``.
The graph (by default gtsam's Data/w10000.graph) arrives ``step`` poses at a time: the new
poses come without values, with every edge whose two ends have arrived, and
a ``Smoother`` optimises after each step (warm start). The reference optimises each prefix as
a new graph (its default initialisation). Times count the ``optimize`` calls only. With
``--robust``, every call is robust, and ``--false-loops`` first adds that share of seeded false
loop closures (``posegraph_datasets.outliers``); the last calls' rejection rates are reported.

With ``--gtsam``, the same stream also goes into gtsam, with default parameters
(``gtsam_stream``): Levenberg-Marquardt over the whole graph from its last estimate after every
step, as posegraph's warm start does, and iSAM2, updated once per step. Their times count
gtsam's calls only. ``--isam2`` streams into posegraph and iSAM2 alone, and compares each one's
last error with one batch solve of the whole graph (no prefix is solved from scratch): the
comparison a back end's user makes, in a time that streams of one pose per call allow.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from posegraph_datasets.outliers import add_false_loops, rejection_rates
from posegraph_datasets.paths import benchmark_or_gtsam_graph

from ..api import optimize
from ..graph import PoseGraph
from ..io import load_graph
from ..lie import LieGroup
from ..robust.run import DECISIONS_AS_START
from ..smoother import COMPOSED, RESTART, SKIPPED, Smoother
from ..smoother.composition import compose_new_nodes
from ..solvers import SolverOptions, Summary
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


_GTSAM_LABELS = {
    "lm": "Levenberg-Marquardt from its last estimate",
    "isam2": "iSAM2, one update per step",
}


def gtsam_stream(
    full: PoseGraph, step: int, methods: tuple[str, ...] = ("lm", "isam2")
) -> dict[str, tuple[list[float], float, str | None]]:
    """``full`` streamed (``stream``) into gtsam's Levenberg-Marquardt ("lm"), re-optimising the
    whole graph from its last estimate after every step, and into iSAM2 ("isam2"), updated once
    per step (both with gtsam's default parameters), those of ``methods``. New nodes start from
    each one's own estimate, composed as posegraph's warm start composes them (``_composed``);
    the first node is held at its value. Returns per
    method (the seconds of each of its calls, final error ½ Σ rᵀΩr, None), or where gtsam
    raised (an indeterminate linear system), (the calls before, NaN, what it raised and where)."""
    import gtsam

    from ..validation import gtsam_bridge as bridge

    factors, isam = gtsam.NonlinearFactorGraph(), gtsam.ISAM2(gtsam.ISAM2Params())
    estimates = {method: gtsam.Values() for method in methods}
    seconds: dict[str, list[float]] = {method: [] for method in methods}
    running, failures, count, edges = list(methods), {}, 0, 0
    for k, graph in enumerate(stream(full, step)):
        new_nodes = np.arange(count, graph.num_nodes)
        new = bridge.between_factors(graph, np.arange(edges, graph.num_edges))
        if count == 0:
            new.push_back(bridge.held_priors(graph, np.arange(1), graph.values))
        factors.push_back(new)
        for method in list(running):
            values = _composed(graph, estimates[method], count)
            start_values = bridge.values_to_gtsam(graph, new_nodes, values)
            start = time.perf_counter()
            try:
                estimates[method] = _gtsam_step(
                    method, factors, new, estimates[method], start_values, isam
                )
            except RuntimeError as error:
                message = " ".join(str(error).strip().split("\n\n")[0].split())
                failures[method] = f"step {k + 1}: {message}"
                running.remove(method)
                continue
            seconds[method].append(time.perf_counter() - start)
        count, edges = graph.num_nodes, graph.num_edges
    return {
        method: (seconds[method], np.nan, failures[method])
        if method in failures
        else (seconds[method], factors.error(estimates[method]), None)
        for method in methods
    }


def _gtsam_step(method: str, factors, new, estimate, start_values, isam):
    """One step of ``method``, its new estimate: Levenberg-Marquardt over all ``factors`` from
    ``estimate`` with the new nodes' ``start_values``, or iSAM2's update by the ``new`` factors."""
    import gtsam

    if method == "lm":
        estimate.insert(start_values)
        params = gtsam.LevenbergMarquardtParams()
        return gtsam.LevenbergMarquardtOptimizer(factors, estimate, params).optimize()
    isam.update(new, start_values)
    return isam.calculateEstimate()


def _composed(graph: PoseGraph, estimate, count: int) -> LieGroup:
    """Values of every node of a step of gtsam's stream (set in ``graph``, the stream's own):
    the new nodes, from the ``count``-th on, composed as posegraph's warm start composes them
    (``compose_new_nodes``) from gtsam's ``estimate`` of the old nodes that their edges reach
    (at the first step, from the first node's own value)."""
    from ..validation import gtsam_bridge as bridge

    if count:
        edges = graph.edges
        new = (edges.i >= count) | (edges.j >= count)
        ends = np.concatenate([edges.i[new], edges.j[new]])
        reached = np.unique(ends[ends < count])
        known = bridge.values_from_gtsam(graph, estimate, reached)
        graph.set_values(graph.values.set_at(reached, known), check=False)
    compose_new_nodes(graph, np.arange(graph.num_nodes) >= max(count, 1))
    return graph.values


def run(
    path: Path,
    step: int,
    robust: str | None = None,
    false_loops: float = 0.0,
    seed: int = 0,
    with_gtsam: bool = False,
) -> str:
    full = load_graph(str(path)).graph
    false = np.zeros(full.num_edges, dtype=bool)
    if false_loops:
        full, false = add_false_loops(full, false_loops, seed)
    rows, warm_calls, scratch_total, graph = _streamed(full, step, robust)
    warm_total = float(np.sum(warm_calls))
    last_warm, last_scratch = rows[-1][1], rows[-1][2]
    difference = (last_warm.final_error - last_scratch.final_error) / last_scratch.final_error
    iterations = np.mean([w.num_iterations for _, w, _ in rows])
    scratch_iterations = np.mean([s.num_iterations for _, _, s in rows])
    restarts = sum(w.initialization == RESTART for _, w, _ in rows[1:])
    composed = sum(w.termination == COMPOSED for _, w, _ in rows[1:])
    from_decisions = sum(
        any(DECISIONS_AS_START in reuse for reuse in w.reused) for _, w, _ in rows[1:]
    )
    lines = [
        f"{path.name}: {full.num_nodes} poses streamed in steps of {step} ({len(rows)} optimisations)",
        f"  warm starts:   total {warm_total:.2f} s, {iterations:.1f} iterations per call on average,"
        f" {restarts} of {len(rows) - 1} restarted from chordal (new measurements disagreed),"
        f" {composed} solved nothing (new poses hanging off the last solution by a tree)"
        + (
            f", {from_decisions} searched on from GNC's last decisions (with the new"
            " measurements kept)"
            if robust is not None
            else ""
        ),
        f"  from scratch:  total {scratch_total:.2f} s, {scratch_iterations:.1f} iterations per call"
        f" (the last, on the whole graph: {last_scratch.total_time:.2f} s)",
        f"  ratio warm / scratch: {warm_total / scratch_total:.3f}",
        f"  warm starts per call: {_latency(warm_calls)}",
        f"  final error: warm {last_warm.final_error:.10g}, scratch {last_scratch.final_error:.10g}"
        f" (relative difference {difference:+.1e})",
        f"  last call reused: {', '.join(last_warm.reused) or 'nothing'}",
    ]
    if with_gtsam:
        lines += _gtsam_lines(full, step, warm_calls, last_scratch.final_error)
    if robust is not None:
        streamed_false = false[np.argsort(arrivals(full, step)[1], kind="stable")]
        lines.append(
            f"  robust {last_warm.robust}, {false.sum()} false loops (seed {seed}): the last calls"
            f" reject {_rates(graph, streamed_false, last_warm)} (warm),"
            f" {_rates(graph, streamed_false, last_scratch)} (scratch)"
        )
    return "\n".join(lines)


def run_against_isam2(path: Path, step: int, skip_within: float = 0.0) -> str:
    """posegraph's ``Smoother`` and iSAM2 fed the same stream, side by side (``--isam2``): their
    totals and per-call latencies, and their last errors against one batch solve's. With
    ``skip_within`` (``SolverOptions``), posegraph's calls may skip their solve, and one more
    call with the defaults, timed with the others, ends the stream at the optimum."""
    full = load_graph(str(path)).graph
    options = SolverOptions(skip_within=skip_within)
    rows, warm_calls, _, _ = _streamed(full, step, None, False, options, finish=skip_within > 0)
    last, batch = rows[-1][1], optimize(full.copy()).summary.final_error
    skipped = sum(w.termination.startswith(SKIPPED) for _, w, _ in rows)
    lines = [
        f"{path.name}: {full.num_nodes} poses streamed in steps of {step} ({len(rows)} calls)",
        f"  posegraph's Smoother: total {np.sum(warm_calls):.2f} s, per call"
        f" {_latency(warm_calls)}, final error {last.final_error:.10g}"
        f" ({(last.final_error - batch) / batch:+.1e} relative to a batch solve's {batch:.10g})"
        + (
            f"; skip_within {skip_within:g}: {skipped} calls skipped their solve, the last"
            f" (defaults) took {1e3 * warm_calls[-1]:.1f} ms"
            if skip_within > 0
            else ""
        ),
    ]
    return "\n".join(lines + _gtsam_lines(full, step, warm_calls, batch, ("isam2",)))


def _gtsam_lines(
    full: PoseGraph,
    step: int,
    warm_calls: list[float],
    optimum: float,
    methods: tuple[str, ...] = ("lm", "isam2"),
) -> list[str]:
    """The report of the same stream into gtsam (``gtsam_stream``), beside posegraph's calls;
    errors relative to ``optimum``."""
    lines = []
    for method, (calls, error, failure) in gtsam_stream(full, step, methods).items():
        seconds = float(np.sum(calls))
        if failure is not None:
            lines.append(
                f"  gtsam {_GTSAM_LABELS[method]}: raised at {failure}"
                f" ({seconds:.2f} s over the steps before)"
            )
            continue
        p99 = np.percentile(warm_calls, 99) / np.percentile(calls, 99)
        lines.append(
            f"  gtsam {_GTSAM_LABELS[method]}: total {seconds:.2f} s (posegraph's warm starts"
            f" take {np.sum(warm_calls) / seconds:.2f}×), final error {error:.10g}"
            f" ({(error - optimum) / optimum:+.1e} relative to the reference solution's);"
            f" per call {_latency(calls)} (posegraph's p99 {p99:.2f}×)"
        )
    return lines


def _latency(calls: list[float]) -> str:
    """Per-call times: median, 99th percentile and largest, in milliseconds."""
    median, p99, largest = 1e3 * np.percentile(calls, [50, 99, 100])
    return f"median {median:.2f} ms, p99 {p99:.2f} ms, max {largest:.2f} ms"


def _streamed(
    full: PoseGraph,
    step: int,
    robust: str | None,
    scratch: bool = True,
    options: SolverOptions | None = None,
    finish: bool = False,
):
    """The stream into one ``Smoother`` with ``options`` and, beside it where ``scratch``, each
    prefix optimised from scratch: the (nodes, warm summary, scratch summary or None) of every
    step, the seconds of each warm call, the total time from scratch, and the graph. With
    ``finish``, one more call with the default options follows the last step."""
    warm_calls, scratch_total, rows, smoother = [], 0.0, [], None
    for graph in stream(full, step):
        smoother = smoother or Smoother(graph)
        start = time.perf_counter()
        warm = smoother.optimize(robust=robust, options=options)
        warm_calls.append(time.perf_counter() - start)
        reference = None
        if scratch:
            prefix = graph.copy()
            start = time.perf_counter()
            reference = optimize(prefix, robust=robust).summary
            scratch_total += time.perf_counter() - start
        rows.append((graph.num_nodes, warm.summary, reference))
    if finish:
        start = time.perf_counter()
        warm = smoother.optimize(robust=robust)
        warm_calls.append(time.perf_counter() - start)
        rows.append((graph.num_nodes, warm.summary, None))
    return rows, warm_calls, scratch_total, graph


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
    peers = parser.add_mutually_exclusive_group()
    peers.add_argument(
        "--gtsam", action="store_true", help="stream into gtsam LM and iSAM2 too, side by side"
    )
    peers.add_argument(
        "--isam2",
        action="store_true",
        help="stream into posegraph and iSAM2 alone, the last errors against one batch solve",
    )
    parser.add_argument(
        "--skip-within",
        type=float,
        default=0.0,
        help="with --isam2: SolverOptions.skip_within of posegraph's calls, then a last call",
    )
    args = parser.parse_args()
    path = Path(args.graph) if args.graph else benchmark_or_gtsam_graph("w10000.graph")
    if path is None:
        raise SystemExit("no graph given and gtsam's Data/ is not installed")
    if args.isam2:
        print(run_against_isam2(path, args.step, args.skip_within))
    else:
        print(run(path, args.step, args.robust, args.false_loops, args.seed, args.gtsam))


if __name__ == "__main__":
    main()
