"""``Solution``: what a ``Smoother``'s last solve left, kept for the next call (warm starts,
GNC's decisions, the weights of covariances and of the rejected measurements)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import EdgeSet, renumbered
from ..lie import LieGroup
from ..robust.spec import RobustSpec
from ..solvers import Summary


@dataclasses.dataclass(frozen=True, eq=False)
class GncProblem:
    """A GNC problem solved to its end: the spec (kernel and width) and which measurements were
    under the kernel (the between edges, then the priors where they were too)."""

    spec: RobustSpec
    measured: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class Solution:
    """What a ``Smoother``'s last solve left in its graph's values: the optimum over these
    between edges and priors, with each one's weight there (1 in least squares; a robust
    kernel's IRLS weight ρ′(s), 0 for a measurement that graduated non-convexity rejected)."""

    edges: EdgeSet
    priors: EdgeSet
    edge_weights: np.ndarray
    prior_weights: np.ndarray
    fixed: np.ndarray
    """Which of the nodes then in the graph were held."""
    values: LieGroup
    """The values it left, one per node then in the graph."""
    summary: Summary
    """The summary of the call that left them (whether it converged, the cost there, …)."""
    gnc: GncProblem | None = None
    """The robust problem whose graduated non-convexity ran to its end here; None in least
    squares, with an IRLS kernel, or where the run stopped early. A later call may carry its
    decisions (``warm_start.previous_decisions``)."""
    debt: float | None = 0.0
    """Where the last solve converged (``summary.converged``), how much the cost at ``values``
    may exceed the optimum's over ``edges`` and ``priors``: 0 after the solve, the cost of the
    measurements added since after calls that skipped their solve (``warm_start.skipped_debt``).
    None once a removal left what remains of it (``without``), so that a later call solves
    again."""

    @classmethod
    def least_squares(
        cls, edges: EdgeSet, priors: EdgeSet, fixed: np.ndarray, values: LieGroup, summary: Summary
    ) -> Solution:
        """A least-squares solution: every measurement of weight 1."""
        return cls(edges, priors, np.ones(len(edges)), np.ones(len(priors)), fixed, values, summary)

    def without(self, nodes: np.ndarray, edges: np.ndarray, priors: np.ndarray) -> Solution:
        """What remains of this solution once the nodes, edges and priors where these masks
        (over its own) hold were removed: the other measurements, renumbered, with their
        weights, rejections and GNC problem, and the values and holds of the other nodes. The
        values are no longer an optimum (``optimal``)."""
        index = renumbered(~nodes)
        summary = dataclasses.replace(
            self.summary,
            rejected_edges=_kept_indices(self.summary.rejected_edges, edges),
            rejected_priors=_kept_indices(self.summary.rejected_priors, priors),
        )
        gnc = None
        if self.gnc is not None:  # its mask covers the edges, then the priors if they were in
            measured = self.gnc.measured
            kept = np.concatenate([~edges, ~priors])[: measured.size]
            gnc = GncProblem(self.gnc.spec, measured[kept])
        return Solution(
            self.edges.subset(~edges).reindexed(index),
            self.priors.subset(~priors).reindexed(index),
            self.edge_weights[~edges],
            self.prior_weights[~priors],
            self.fixed[~nodes],
            self.values[~nodes],
            summary,
            gnc,
            debt=None,
        )

    def weights_for(self, edges: EdgeSet, priors: EdgeSet) -> tuple[np.ndarray, np.ndarray]:
        """The weights of ``edges`` and of ``priors``: the solution's for the measurements it was
        found over, if they still come first and unchanged, and 1 for those added since (1 for
        all of a kind if some of it were changed, or removed other than by the ``Smoother``'s
        removals, which carry the solution: ``without``)."""
        return (
            _carried(edges, self.edges, self.edge_weights, 1.0),
            _carried(priors, self.priors, self.prior_weights, 1.0),
        )

    def appended_weights(self, num_edges: int) -> tuple[np.ndarray, np.ndarray]:
        """The weights of a graph's ``num_edges`` between edges and of its priors where it grew
        since this solution by appended nodes and edges alone (``Growth.appended``, already
        tested): this solution's, then 1 for each edge appended."""
        appended = np.ones(num_edges - len(self.edges))
        return np.concatenate([self.edge_weights, appended]), self.prior_weights.copy()

    def rejected_for(self, edges: EdgeSet, priors: EdgeSet) -> tuple[np.ndarray, np.ndarray]:
        """Masks over ``edges`` and over ``priors`` of the measurements that this solution's
        robust run rejected (``summary.rejected_edges`` and ``rejected_priors``), by the rule of
        ``weights_for``: none of those added since (none of a kind if some of it were changed,
        or removed other than by the ``Smoother``'s removals)."""
        rejected = []
        for measured, solved, indices in (
            (edges, self.edges, self.summary.rejected_edges),
            (priors, self.priors, self.summary.rejected_priors),
        ):
            flags = np.zeros(len(solved), dtype=bool)
            flags[indices] = True
            rejected.append(_carried(measured, solved, flags, False))
        return rejected[0], rejected[1]


def _kept_indices(indices: list[int], removed: np.ndarray) -> list[int]:
    """``indices`` into a sequence, renumbered for the sequence without the ``removed`` ones."""
    index = renumbered(~removed)
    return [int(index[k]) for k in indices if not removed[k]]


def _carried(measured: EdgeSet, solved: EdgeSet, values: np.ndarray, added) -> np.ndarray:
    """``values`` (one per solved measurement) for ``measured``, if it starts with exactly the
    ``solved`` ones; ``added`` for those after them, and for all if it does not."""
    carried = np.full(len(measured), added, dtype=values.dtype)
    if measured.starts_with(solved):
        carried[: len(solved)] = values
    return carried
