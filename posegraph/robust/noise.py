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
from ..problem.backends import inverts_selectively
from ..problem.factors import between_squares, prior_squares
from ..solvers import Result
from .kernels import default_width
from .leverage import Leverage, deleted_residuals

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


GAP = 4.0
"""A jump of this factor between consecutive tests (d² over its limit, under the median
scales) above ``OFF_BY`` ends a heavy tail of true measurements (``tail_end``)."""
TAIL_MAX = 100.0
"""A heavy tail reaches at most this many times the limit."""
TAIL_MEMBERS = 10
"""A heavy tail holds at least this many measurements beyond ``OFF_BY`` times the limit: one
or two beyond it and a jump are false measurements near the true ones."""


@dataclasses.dataclass(frozen=True)
class NoiseClass:
    """One class of measurement at a solution: how many, their redundancy (Σ tr(I − Mₑₑ)),
    Σ s / redundancy (1 when the information is right), and how many fail the test."""

    kind: str
    count: int
    redundancy: float
    chi2_per_dof: float | None
    above_quantile: int

    def off_by(self, factor: float) -> bool:
        """Whether Σ s / redundancy is beyond ``factor`` either way; residuals below
        ``NOISE_FREE`` per degree of freedom (a file made without noise) say nothing."""
        ratio = self.chi2_per_dof
        return ratio is not None and ratio > NOISE_FREE and not 1 / factor <= ratio <= factor

    def finding(self, robust: bool = False) -> tuple[str, str] | None:
        """(what a user should hear about this class, what to do), if anything; ``robust``:
        of the measurements a robust run kept, where failing tests are not news."""
        ratio = self.chi2_per_dof
        many = self.above_quantile > max(1, FALSE_SHARE * self.count)
        if self.kind == "loop closures" and many and not robust:
            return (
                f"{self.above_quantile} of {self.count} loop closures fail the χ²({QUANTILE})"
                " test against the solution without them: likely false loops",
                "try --robust gnc",
            )
        if not self.off_by(OFF_BY):
            return None
        measured = f"χ² per degree of freedom {ratio:.3g}, 1 when it is right"
        if ratio < 1 / OFF_BY:
            return (
                f"the information of the {self.kind} overstates their noise about"
                f" {1 / ratio:.2g}× ({measured})",
                "--calibrate-noise scales the information"
                if robust
                else "a robust kernel's default width then keeps false measurements:"
                " --calibrate-noise scales the information (--robust gnc does where it hides"
                " outliers)",
            )
        return (
            f"the information of the {self.kind} understates their noise about {ratio:.2g}×"
            f" ({measured}), or some are false",
            "try --robust gnc; if the residuals are all alike, --calibrate-noise",
        )

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


KINDS = ("odometry", "loop closures", "priors")


def measurement_kinds(graph: PoseGraph) -> np.ndarray:
    """Each measurement's class as an index into ``KINDS``: the between edges (odometry
    between consecutive nodes, loop closures otherwise), then the priors."""
    between = np.where(odometry_mask(graph), 0, 1)
    return np.concatenate([between, np.full(len(graph.priors), 2)]).astype(np.int64)


@dataclasses.dataclass(frozen=True)
class MeasurementTests:
    """Every measurement's test at a least-squares solution, the between edges then the priors:
    its class (``measurement_kinds``), s = rᵀΩr, redundancy tr(I − Mₑₑ) (a prior's: its rank),
    the tested quantity (an edge's deleted residual d², a prior's s), the rank of its
    information and the limit χ²_rank(``QUANTILE``)."""

    kinds: np.ndarray
    squares: np.ndarray
    redundancy: np.ndarray
    tested: np.ndarray
    rank: np.ndarray
    limits: np.ndarray

    def classes(self, inliers: np.ndarray | None = None) -> list[NoiseClass]:
        """The classes over the measurements where ``inliers`` holds (all by default), in
        ``KINDS`` order, those without measurements left out."""
        inliers = np.ones(self.kinds.size, dtype=bool) if inliers is None else inliers
        classes = []
        for index, kind in enumerate(KINDS):
            mask = (self.kinds == index) & inliers
            if mask.any():
                total = float(self.redundancy[mask].sum())
                ratio = float(self.squares[mask].sum() / total) if total > 0 else None
                failing = int(np.count_nonzero(self.tested[mask] > self.limits[mask]))
                classes.append(NoiseClass(kind, int(mask.sum()), total, ratio, failing))
        return classes


def measurement_tests(
    graph: PoseGraph,
    values: LieGroup,
    solved: Result | None = None,
    leverage: Leverage | None = None,
) -> MeasurementTests:
    """The tests of the graph's measurements at ``values``, a least-squares solution (that of
    ``solved``, if given: its normal equations are reused, ``leverage.deleted_residuals``).
    ``leverage``, of this graph at ``values``, lends its deleted residuals where they are
    exact (CHOLMOD's)."""
    edge_ranks = information_ranks(graph.edges.information)
    prior_ranks = information_ranks(graph.priors.information)
    prior_s = prior_squares(values, graph.priors)
    edge_s, redundancy, innovation = np.zeros(0), np.zeros(0), np.zeros(0)
    if graph.num_edges:
        exact = leverage is not None and inverts_selectively(leverage.linear_solver)
        deleted = (
            leverage.deleted_residuals if exact else deleted_residuals(graph, values, solved=solved)
        )
        unmeasured = graph.group.dof - edge_ranks  # directions I − Mₑₑ counts as 1 that s lacks
        edge_s = between_squares(values, graph.edges)
        redundancy = np.maximum(deleted.redundancy - unmeasured, 0.0)
        innovation = deleted.innovation
    ranks = np.concatenate([edge_ranks, prior_ranks])
    return MeasurementTests(
        measurement_kinds(graph),
        np.concatenate([edge_s, prior_s]),
        np.concatenate([redundancy, prior_ranks.astype(float)]),
        np.concatenate([innovation, prior_s]),
        ranks,
        limits(ranks),
    )


def limits(ranks: np.ndarray) -> np.ndarray:
    """χ²_rank(``QUANTILE``) of each rank (∞ for 0: nothing measured, nothing to test)."""
    distinct, index = np.unique(ranks, return_inverse=True)
    of_distinct = [default_width(int(k), QUANTILE) ** 2 if k else np.inf for k in distinct]
    return np.array(of_distinct, dtype=float)[index.reshape(np.shape(ranks))]


def beyond_tail(ratios: np.ndarray, among: np.ndarray) -> np.ndarray:
    """Where ``ratios`` (test over limit) are gross: beyond ``tail_end`` of those ``among``."""
    return ratios > tail_end(ratios[among])


def tail_end(ratios: np.ndarray) -> float:
    """The ratio of test to limit beyond which a measurement is gross: ``OFF_BY``, or the start
    of a jump of ``GAP`` where at least ``TAIL_MEMBERS`` ratios run on from ``OFF_BY`` to it
    in smaller steps and it is at most ``TAIL_MAX``: a tail of true measurements whose noise is
    heavier than a Gaussian's, apart from the gross outliers (parking-garage's true loops;
    ``docs/architecture.md``). The largest ratio ends such a tail where no jump follows and
    the tail holds at most ``FALSE_SHARE`` of the ratios: more, running on smoothly, are false
    measurements that a narrow width pulled apart (w10000's, at 10% false loops)."""
    ascending = np.sort(ratios[np.isfinite(ratios)])
    start = max(np.searchsorted(ascending, OFF_BY, side="right") - 1, 0)
    above = np.append(ascending[start:], np.inf)  # the end of the ratios as a jump
    jumps = np.flatnonzero(above[1:] >= GAP * above[:-1])
    if not jumps.size or not OFF_BY < above[jumps[0]] <= TAIL_MAX:
        return OFF_BY
    members = np.count_nonzero(above[: jumps[0] + 1] > OFF_BY)
    last = jumps[0] == above.size - 2
    if members < TAIL_MEMBERS or (last and members > FALSE_SHARE * ascending.size):
        return OFF_BY
    return float(above[jumps[0]])


def noise_consistency(
    graph: PoseGraph, values: LieGroup, solved: Result | None = None
) -> list[NoiseClass]:
    """The classes of the graph's measurements at ``values``, a least-squares solution (that of
    ``solved``, if given): odometry, loop closures, priors (whose redundancy is taken as their
    rank; the test is on s). Classes without measurements are left out."""
    return measurement_tests(graph, values, solved).classes()
