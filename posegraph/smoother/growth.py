"""``Growth``: what was added to a smoother's graph since its last solution, each test of it made
once per call (a streamed call asks several of them, on the same arrays)."""

from __future__ import annotations

import functools

import numpy as np

from ..graph import EdgeSet, PoseGraph, connected_components, information_ranks
from ..problem.factors import chi2
from .solution import Solution


class Growth:
    """The graph against its last ``solution``: whether the solution's measurements still come
    first and unchanged, whether the graph grew by appended nodes and between edges alone, or by
    a tree of them, and the measurements appended since. Composing and refining the new nodes
    leaves the solved nodes' values as they were, so ``values_kept`` holds throughout a warm
    start; ``added_chi2`` is read once the new nodes have their start values."""

    def __init__(self, graph: PoseGraph, solution: Solution) -> None:
        self.graph, self.solution = graph, solution
        self.old_nodes = len(solution.fixed)

    @functools.cached_property
    def measurements_kept(self) -> bool:
        """Whether the solution's edges and priors come first and unchanged in the graph."""
        graph, solution = self.graph, self.solution
        return graph.edges.starts_with(solution.edges) and graph.priors.starts_with(solution.priors)

    @functools.cached_property
    def appended(self) -> bool:
        """Whether the graph grew by appended nodes and between edges alone: nothing was removed
        since (``Solution.debt``), the solution's measurements come first and unchanged, and no
        prior and no hold is new."""
        graph, solution, old = self.graph, self.solution, self.old_nodes
        return (
            solution.debt is not None
            and len(graph.priors) == len(solution.priors)
            and np.array_equal(graph.fixed[:old], solution.fixed)
            and not graph.fixed[old:].any()
            and self.measurements_kept
        )

    @functools.cached_property
    def tree(self) -> bool:
        """Whether all that was added is a tree of between edges that hangs the new nodes off
        the solved ones (``appended``, and no cycle is new). Each new node then has one place
        that fits its edges exactly, and the problem over the solved nodes is as it was."""
        edges = self.new_edges
        return (
            _hangs_a_tree(edges.i, edges.j, self.old_nodes, self.graph.num_nodes) and self.appended
        )

    @functools.cached_property
    def values_kept(self) -> bool:
        """Whether the solved nodes still hold the solution's values."""
        return self.graph.values[: self.old_nodes].same_as(self.solution.values)

    @functools.cached_property
    def new_edges(self) -> EdgeSet:
        """The between edges after the solution's."""
        return self.graph.edges.subset(slice(len(self.solution.edges), None))

    @functools.cached_property
    def new_priors(self) -> EdgeSet:
        """The priors after the solution's."""
        return self.graph.priors.subset(slice(len(self.solution.priors), None))

    @functools.cached_property
    def new_ranks(self) -> np.ndarray:
        """rank Ω of each new between edge."""
        return information_ranks(self.new_edges.information)

    @functools.cached_property
    def added_chi2(self) -> float:
        """Σ rᵀΩr of the new edges and priors at the graph's values (the start's)."""
        return chi2(self.graph.values, self.new_edges, self.new_priors)


def _hangs_a_tree(i: np.ndarray, j: np.ndarray, old: int, count: int) -> bool:
    """Whether edges (i, j) over nodes 0 … count − 1 form a tree over the nodes from ``old`` on
    and the nodes before ``old`` taken as one: one edge per new node, and all connected."""
    new = count - old
    if len(i) != new:
        return False
    # The old nodes become node 0, and new node k becomes k − old + 1.
    ends = np.maximum(np.stack([i, j]) - old + 1, 0)
    return bool(connected_components(new + 1, ends[0], ends[1]).max() == 0)
