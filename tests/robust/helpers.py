"""Helpers shared by the tests of initialisation, observability and robust estimation."""

from __future__ import annotations

import numpy as np

from posegraph.graph import PoseGraph
from posegraph.lie import SE3
from posegraph.problem import observability
from posegraph.problem.observability import (
    undetermined_direction,
)

from ..conftest import (
    gnss_track,
)


def factorised_direction(graph: PoseGraph, monkeypatch) -> np.ndarray | None:
    """``undetermined_direction`` found by factorising H₁, even where the graph is tied by
    measurements of full rank."""
    with monkeypatch.context() as patch:
        patch.setattr(observability, "tied_by_full_rank", lambda graph: False)
        return undetermined_direction(graph, graph.values)


def gnss_with_a_bad_fix(offset: float) -> PoseGraph:
    """``gnss_track`` (SE3, position-only fixes of σ 1 m) with its 6th fix moved ``offset``
    metres sideways."""
    graph, _ = gnss_track(SE3, 0.3, seed=4)
    fixes = graph.priors.measurements.as_matrix()
    fixes[5, 1, 3] += offset
    graph.priors = graph.priors.__class__(
        graph.priors.i, graph.priors.j, SE3.from_matrix(fixes), graph.priors.information
    )
    return graph
