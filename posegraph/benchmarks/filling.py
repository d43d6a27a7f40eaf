"""Least squares where false loops fill the Cholesky factor: CHOLMOD against conjugate gradients
(``posegraph.problem.iterative``), on the same graph from the same start, one after the other.

Usage: ``python -m posegraph.benchmarks.filling [--graphs w10000 sphere2500] [--generator
project] [--fractions 0.1] [--seed 0]``. Each graph gets false loops (``false_loops``'
generators) and is solved from its odometry with ``linear_solver="cholmod"`` and with "auto",
which takes conjugate gradients where CHOLMOD's predicted factorisation flops per entry pass
``FLOPS_PER_ENTRY``. Prints a markdown table: the predicted flops per entry, each run's time,
iterations and final error ½ Σ rᵀΩr, and the time ratio.
"""

from __future__ import annotations

import argparse
import time

from ..api import optimize
from ..problem.backends import predicted_flops_per_entry
from ..problem.linear import NormalEquations
from ..solvers import SolverOptions
from .false_loops import GENERATORS, load
from .table import MarkdownTable


def _run(graph, solver: str) -> tuple[float, object]:
    began = time.perf_counter()
    result = optimize(graph.copy(), init="odometry", options=SolverOptions(linear_solver=solver))
    return time.perf_counter() - began, result.summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--graphs", nargs="*", default=["w10000", "sphere2500"])
    parser.add_argument("--generator", default="project", choices=GENERATORS)
    parser.add_argument("--fractions", nargs="*", type=float, default=[0.1])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    table = MarkdownTable(
        "graph | false loops | predicted flops per entry | auto takes | CHOLMOD (s) | auto (s) "
        "| ratio | iterations CHOLMOD / auto | final error CHOLMOD / auto",
        echo=True,
    )
    for name in args.graphs:
        for fraction in args.fractions:
            graph, _ = GENERATORS[args.generator](load(name), fraction, args.seed)
            system = NormalEquations(graph, graph.gauge_nodes(), "cholmod")
            per_entry = predicted_flops_per_entry(system.cholesky, system.indices.size)
            direct_time, direct = _run(graph, "cholmod")
            auto_time, auto = _run(graph, "auto")
            table.add(
                f"{name} | {args.generator} {fraction:g} | {per_entry:.3g} | "
                f"{auto.linear_solver} | {direct_time:.1f} | {auto_time:.1f} | "
                f"{auto_time / direct_time:.2f} | "
                f"{len(direct.iterations)} / {len(auto.iterations)} | "
                f"{direct.final_error:.10g} / {auto.final_error:.10g}"
            )


if __name__ == "__main__":
    main()
