"""Graphs and helpers shared by the back end's tests (the smoother and its covariances)."""

from __future__ import annotations

import numpy as np

from posegraph.graph import PoseGraph
from posegraph.lie import SE2
from posegraph.problem.linear import NormalEquations
from posegraph.robust.run import DECISIONS_AS_START


def drive_on(graph: PoseGraph, poses: int) -> None:
    """Append ``poses`` new poses without values, each by an odometry edge from the last."""
    last = int(graph.node_ids[-1])
    for k in range(last + 1, last + 1 + poses):
        graph.add_node(k)
        graph.add_edge(k - 1, k, SE2.from_xytheta([1.0, 0.1, 0.05]), np.eye(3) * 100.0)


def searched_from_decisions(summary) -> bool:
    return any(DECISIONS_AS_START in reuse for reuse in summary.reused)


def count_normal_equations(monkeypatch) -> list:
    """A list that grows by one whenever ``NormalEquations`` are built."""
    built, init = [], NormalEquations.__init__

    def counted(self, *args, **kwargs):
        built.append(1)
        init(self, *args, **kwargs)

    monkeypatch.setattr(NormalEquations, "__init__", counted)
    return built
