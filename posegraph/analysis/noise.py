"""Noise consistency of a least-squares solution, per class of measurement (odometry, loop
closures, priors): Σ s / Σ redundancy, with s = rᵀΩr at the solution and an edge's redundancy
tr(I − Mₑₑ) (the expectation of its s when the information states the noise right; Förstner
1979, Baarda 1968), which is 1 then; and how many measurements fail Baarda's test, their
deleted residual d² (``robust.leverage``) above χ²_rank(0.999)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph, odometry_mask
from ..graph.checks import information_ranks
from ..lie import LieGroup
from ..problem.factors import between_squares, prior_squares
from ..robust.kernels import default_width
from ..robust.leverage import deleted_residuals

QUANTILE = 0.999
"""The quantile of χ²_rank beyond which a measurement fails the test."""

OFF_BY = 10.0
"""A class whose Σ s / Σ redundancy is beyond this factor either way is named: its
information misstates its noise."""

NOISE_FREE = 1e-12
"""Below this χ² per degree of freedom the residuals are rounding: a file made without noise,
whose information cannot be tested."""

FALSE_SHARE = 0.01
"""Loop closures failing the test beyond this share of them (ten times the test's own rate)
are named as likely false."""


@dataclasses.dataclass(frozen=True)
class NoiseClass:
    """One class of measurement at a solution: how many, their redundancy (Σ tr(I − Mₑₑ)),
    Σ s / redundancy (1 when the information is right), and how many fail the test."""

    kind: str
    count: int
    redundancy: float
    chi2_per_dof: float | None
    above_quantile: int

    def finding(self) -> tuple[str, str] | None:
        """(what a user should hear about this class, what to do), if anything. Residuals
        below ``NOISE_FREE`` per degree of freedom (a file made without noise) say nothing."""
        ratio = self.chi2_per_dof
        if self.kind == "loop closures" and self.above_quantile > max(1, FALSE_SHARE * self.count):
            return (
                f"{self.above_quantile} of {self.count} loop closures fail the χ²({QUANTILE})"
                " test against the solution without them: likely false loops",
                "try --robust gnc",
            )
        if ratio is None or ratio < NOISE_FREE or 1 / OFF_BY <= ratio <= OFF_BY:
            return None
        measured = f"χ² per degree of freedom {ratio:.3g}, 1 when it is right"
        if ratio < 1 / OFF_BY:
            return (
                f"the information of the {self.kind} overstates their noise about"
                f" {1 / ratio:.2g}× ({measured})",
                "a robust kernel's default width then keeps false measurements: narrow it"
                f" about {np.sqrt(1 / ratio):.2g}× (--robust gnc:WIDTH) or scale the information",
            )
        return (
            f"the information of the {self.kind} understates their noise about {ratio:.2g}×"
            f" ({measured}), or some are false",
            "try --robust gnc; if the residuals are all alike, scale the information",
        )

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def noise_consistency(graph: PoseGraph, values: LieGroup) -> list[NoiseClass]:
    """The classes of the graph's measurements at ``values``, a least-squares solution:
    odometry (edges between consecutive nodes), loop closures (the other edges), priors (whose
    redundancy is taken as their rank; the test is on s). Classes without measurements are
    left out."""
    classes = []
    if graph.num_edges:
        deleted = deleted_residuals(graph, values)
        ranks = information_ranks(graph.edges.information)
        unmeasured = graph.group.dof - ranks  # directions I − Mₑₑ counts as 1 that s lacks
        redundancy = np.maximum(deleted.redundancy - unmeasured, 0.0)
        squares = between_squares(values, graph.edges)
        odometry = odometry_mask(graph)
        for kind, mask in (("odometry", odometry), ("loop closures", ~odometry)):
            if mask.any():
                classes.append(
                    _class(
                        kind, squares[mask], redundancy[mask], deleted.innovation[mask], ranks[mask]
                    )
                )
    if len(graph.priors):
        ranks = information_ranks(graph.priors.information)
        squares = prior_squares(values, graph.priors)
        classes.append(_class("priors", squares, ranks.astype(float), squares, ranks))
    return classes


def _class(kind, squares, redundancy, innovations, ranks) -> NoiseClass:
    total = float(redundancy.sum())
    ratio = float(squares.sum() / total) if total > 0 else None
    limits = np.array(
        [default_width(int(rank), QUANTILE) ** 2 if rank else np.inf for rank in ranks]
    )
    return NoiseClass(
        kind, int(squares.size), total, ratio, int(np.count_nonzero(innovations > limits))
    )
