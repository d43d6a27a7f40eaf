"""posegraph against gtsam Levenberg-Marquardt on generated graphs of growing size, side by side.

Usage: ``python -m posegraph.benchmarks.scaling [--repeats 10] [--rounds 2] [--budget 0.2]``.
The graphs are spheres (SE3, ``posegraph_datasets.generators.sphere``), spheres with a docking
station that every pose measures (``docked``: one node that a thousand edges reach) and
Manhattan worlds (SE2, ``manhattan_world``) from 9 to 3000 poses, each starting from its composed
noisy odometry. This shows from what size posegraph's fixed cost per ``optimize`` call (a few
milliseconds of numpy calls, whatever the size) stops dominating. Prints a markdown table: gtsam
from the graph's values, then posegraph from the same values, then posegraph with its defaults
(``init="auto"``, initialisation included); times in milliseconds (best of ``repeats`` runs,
and more until ``budget`` seconds have passed, in each of ``rounds`` rounds, taken in turns:
``optimizer.side_by_side``) and as ratios posegraph/gtsam, and the relative difference of the
final errors ½ Σ rᵀΩr.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from posegraph_datasets.generators import docked, manhattan_world, sphere

from ..graph import PoseGraph
from .optimizer import side_by_side
from .table import MarkdownTable
from .timing import add_timing_arguments

SPHERES = ((3, 3), (4, 8), (8, 12), (10, 16), (16, 25), (25, 40))
"""(rings, poses per ring) of the SE3 spheres."""
DOCKED_SPHERES = ((16, 25), (25, 40), (40, 75))
"""(rings, poses per ring) of the spheres with a docking station."""
MANHATTAN_POSES = (25, 100, 300, 1000, 3000)
"""Poses of the SE2 Manhattan worlds, on a grid of about √poses / 2 cells a side."""


def graphs(seed: int = 1) -> Iterator[tuple[str, PoseGraph]]:
    """The generated graphs and their kinds, smallest first within each kind."""
    for rings, per_ring in SPHERES:
        yield "sphere", sphere(rings, per_ring, seed=seed)[0]
    for rings, per_ring in DOCKED_SPHERES:
        yield "sphere + dock", docked(*sphere(rings, per_ring, seed=seed), seed=seed)[0]
    for poses in MANHATTAN_POSES:
        grid_size = max(3, round(poses**0.5 / 2))
        yield "manhattan", manhattan_world(poses, grid_size=grid_size, seed=seed)[0]


def run(repeats: int, rounds: int = 1, budget: float = 0.0, echo: bool = False) -> str:
    """Benchmark every generated graph; returns the markdown table, printing it row by row if
    ``echo``."""
    table = MarkdownTable(
        "graph | group | poses | edges | gtsam (ms) | iters | posegraph, from the same values (ms) "
        "| iters | ratio | posegraph, defaults (ms) | init | ratio | rel. error diff",
        echo,
    )
    for kind, graph in graphs():
        gtsam_run, same_run, default_run = side_by_side(graph, repeats, rounds, budget)
        gtsam_time, gtsam_iterations, gtsam_error = gtsam_run
        (same_time, same), (default_time, defaults) = same_run, default_run
        difference = (defaults.final_error - gtsam_error) / max(gtsam_error, 1e-300)
        table.add(
            f"{kind} | {graph.group.__name__} | {graph.num_nodes} | {graph.num_edges} "
            f"| {1e3 * gtsam_time:.2f} | {gtsam_iterations} "
            f"| {1e3 * same_time:.2f} | {same.num_iterations} | {same_time / gtsam_time:.2f} "
            f"| {1e3 * default_time:.2f} | {defaults.initialization} "
            f"| {default_time / gtsam_time:.2f} | {difference:+.1e}"
        )
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_timing_arguments(parser, repeats=10)
    args = parser.parse_args()
    run(args.repeats, args.rounds, args.budget, echo=True)


if __name__ == "__main__":
    main()
