"""Noise calibration: one precision scale per class of measurement (odometry, loop closures,
priors), estimated from its inliers' deleted residuals at a least-squares solution and applied
to the class's information, iterated with the solve (variance component estimation: Förstner
1979, "Ein Verfahren zur Schätzung von Varianz- und Kovarianzkomponenten"; Koch 1999,
"Parameter Estimation and Hypothesis Testing in Linear Models", §3.6, made robust).

Two scales per class, from the tests d² (χ²_rank when the information states the noise): the
deleted residuals of the inliers, and the innovations of what a robust solve left out:
- the median scale, median(χ²_rank median / d²) over the inliers: robust to the outliers among
  them, but on real data, whose residuals have heavier tails than a Gaussian's, it fails
  Baarda's test on several per cent of the true measurements;
- the tail scale, the largest at which no more of all the measurements fail the test than it
  lets through, leaving out the gross outliers: beyond ``OFF_BY`` times its limit under the
  median scale, or beyond the end of a heavy tail of true ones (``noise.tail_end``).
A class gets the smaller; in a robust solve that kept gross outliers, the median scale, so that
the next solve rejects them (and the tail scale then re-admits the true measurements of the
heavy tail that it rejected too). Where that wider width brings gross outliers back,
calibration ends there, with the decisions from before it settled at it: the two scales would
otherwise alternate (a true tail that runs on into the false measurements' tests). In least
squares the inliers are the measurements that pass the test.

After a scaling that narrows the width, GNC runs anew (searching locally once the width
holds): decisions settled from false loops kept stay bent around them. After any other, a
robust solve settles the last decisions at the new width (GNC's consistency pass) and
searches locally from them: scaling every class alike leaves the least-squares solution over
a kept set where it was and moves only the width relative to the residuals.

A robust run at the default width calibrates on its own where it kept gross outliers: false
loops that an information overstating the noise let the kernel keep (parking-garage's states
20,000× its noise); where it rejected measurements that the noise of those it kept explains
(more than ``FALSE_SHARE`` of those under the kernel pass the test under the kept ones' median
scales: an information understating the noise, whose narrow width rejected true loops with
the false; GNC then runs anew at the calibrated width, ``robust.second_opinion``); and where
a second opinion at a narrower width replaced a solution that kept none but was wrong
(``robust.second_opinion``). It scales every class alike, by the smallest scale of the
classes under the kernel (the loop closures, by default; odometry that false loops bent says
little): what it corrects is the kernel's width relative to the noise, and the classes'
relative weights, and with them the least-squares solution over a set of inliers, stay the
file's. Where the measurements kept tell nothing of a class's noise (GNC rejected nearly all of
it), only an asked-for calibration estimates it from the rejected ones, taking their majority
as true: on its own, robust mode cannot tell true loops under a width far too narrow from
false ones."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np

from ..graph import PoseGraph
from ..graph.checks import information_ranks
from ..lie import LieGroup
from ..problem.cholesky import NotPositiveDefinite
from ..problem.factors import between_squares, prior_squares
from ..solvers import Result
from .kernels import default_width
from .leverage import Leverage
from .noise import (
    FALSE_SHARE,
    KINDS,
    QUANTILE,
    MeasurementTests,
    NoiseClass,
    beyond_tail,
    limits,
    measurement_kinds,
    measurement_tests,
    noise_consistency,
)

INLIER_PASSES = 5
"""Passes of the least-squares inlier test (each with the scale of the last) at one solution."""
SETTLED = 1.5
"""Calibration stops once every class's new scale is within this factor of 1."""
ROUNDS = 4
"""Solves after the first, at most."""
FEWEST = 10
"""A class with fewer inliers keeps its information."""
REDUNDANT = 0.05
"""Measurements whose redundancy per degree of freedom is below this (that little else
measures) say nothing of the noise: their deleted residual is r̃ᵀ(I − M)⁻¹r̃ with I − M ≈ 0."""


@dataclasses.dataclass(frozen=True)
class Calibration:
    """What calibration did: the factor each class's information was multiplied by, whether it
    ran on its own (``automatic``), the solves it took after the first, whether it began at a
    second opinion's narrower width (``robust.second_opinion``), and how many rejections that
    the kept measurements' noise explains set it off (0 where they did not)."""

    scales: dict[str, float]
    automatic: bool
    solves: int
    second_opinion: bool = False
    consistent_rejections: int = 0

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """Calibration's estimate at one solution: each class's median and tail scales (classes
    without ``FEWEST`` telling inliers left out), the inliers' noise consistency, and how many
    of them are gross outliers."""

    median: dict[str, float]
    tail: dict[str, float]
    classes: list[NoiseClass]
    gross: int
    consistent: int = 0
    """Measurements outside the inliers that pass the test under the median scales (in a class
    without one, the smallest of the others')."""

    def scales(self) -> dict[str, float]:
        """The smaller of the two scales of each class."""
        return {kind: min(scale, self.tail[kind]) for kind, scale in self.median.items()}


def estimate(
    graph: PoseGraph,
    values: LieGroup,
    edge_inliers: np.ndarray | None = None,
    prior_inliers: np.ndarray | None = None,
    majority: bool = True,
    solved: Result | None = None,
) -> Estimate:
    """The estimate at ``values``, a least-squares solution over the given inliers (by default
    every measurement, of which those that pass Baarda's test under their class's scale are
    the inliers). The measurements left out are tested by their innovation against the
    solution (a prior's by its s) and count in the tail scales, so that true ones of a heavy
    tail, rejected under a scale that was too large, pull it back. ``majority``: a class whose
    inliers tell nothing of its noise takes the majority of its others as true (``_estimate``);
    without it, such a class has no scale. ``solved``, the solve that ended at ``values``,
    lends its normal equations where they are those of the inliers."""
    if edge_inliers is None:
        tests = measurement_tests(graph, values, solved)
        inliers = np.ones(tests.kinds.size, dtype=bool)
        found = _estimate(tests, inliers)
        for _ in range(INLIER_PASSES):
            passing = tests.tested * _by_measurement(tests, found.scales()) <= tests.limits
            if np.array_equal(passing, inliers):
                break
            inliers = passing
            found = _estimate(tests, inliers)
        return found
    work = _inliers(graph, edge_inliers, prior_inliers)
    tests = _with_left_out(graph, work, values, edge_inliers, prior_inliers, solved)
    inliers = np.arange(tests.kinds.size) < work.num_edges + len(work.priors)
    return _estimate(tests, inliers, majority)


def _with_left_out(
    graph, work, values, edge_inliers, prior_inliers, solved=None
) -> MeasurementTests:
    """The tests of ``work`` (the inliers), then those of the edges and priors left out, with
    the leverages that ``solved`` carries where they are ``work``'s at ``values``."""
    lent = Leverage.lent_by(solved, work, values)
    tests = measurement_tests(work, values, solved, lent)
    out_edges = graph.edges.subset(~edge_inliers)
    out_priors = graph.priors.subset(~prior_inliers)
    if not len(out_edges) and not len(out_priors):
        return tests
    innovation = np.zeros(0)
    if len(out_edges):
        innovation = (lent or Leverage(work, values)).innovations(out_edges)
    prior_s = prior_squares(values, out_priors)
    ranks = np.concatenate(
        [information_ranks(out_edges.information), information_ranks(out_priors.information)]
    )
    left_out = np.concatenate([~edge_inliers, ~prior_inliers])
    parts = (
        measurement_kinds(graph)[left_out],
        np.concatenate([between_squares(values, out_edges), prior_s]),
        ranks.astype(float),
        np.concatenate([innovation, prior_s]),
        ranks,
        limits(ranks),
    )
    mine = (getattr(tests, field.name) for field in dataclasses.fields(tests))
    joined = [np.concatenate(pair) for pair in zip(mine, parts, strict=True)]
    return MeasurementTests(*joined)


def _estimate(tests: MeasurementTests, inliers: np.ndarray, majority: bool = True) -> Estimate:
    """The estimate from ``tests``: median scales over the ``inliers``, gross outliers among
    all, tail scales over all but the gross ones, and the inliers' noise consistency. A class
    whose inliers tell nothing of its noise (a robust solve rejected nearly all of it) takes,
    with ``majority``, the median scale of its other measurements, whose majority is then
    taken as true (as least median of squares takes it), for its tail scale too: its false
    measurements would set that."""
    telling = (tests.redundancy >= REDUNDANT * tests.rank) & (tests.tested > 0)
    telling &= np.isfinite(tests.tested)
    median = _medians(tests, inliers & telling)
    guessed = _medians(tests, ~inliers & telling) if majority else {}
    guessed = {kind: scale for kind, scale in guessed.items() if kind not in median}
    median |= guessed
    tail = dict(guessed)
    gross = beyond_tail(tests.tested * _by_measurement(tests, median) / tests.limits, telling)
    for index, kind in enumerate(KINDS):
        members = telling & ~gross & (tests.kinds == index)
        if kind in median and kind not in guessed:
            bounds = np.sort(tests.limits[members] / tests.tested[members])
            allowed = max(1, int((1.0 - QUANTILE) * bounds.size))
            tail[kind] = float(bounds[allowed]) if bounds.size > allowed else np.inf
    return Estimate(
        median,
        tail,
        tests.classes(inliers),
        int(np.count_nonzero(gross & inliers)),
        _consistent(tests, ~inliers & telling, median),
    )


def _consistent(tests: MeasurementTests, others: np.ndarray, median: dict[str, float]) -> int:
    """How many of the ``others`` pass the test under the ``median`` scales
    (``Estimate.consistent``; none without any)."""
    if not median:
        return 0
    pooled = dict.fromkeys(KINDS, min(median.values())) | median
    passing = tests.tested * _by_measurement(tests, pooled) <= tests.limits
    return int(np.count_nonzero(passing & others))


def _medians(tests: MeasurementTests, members: np.ndarray) -> dict[str, float]:
    """Each class's median scale over its ``members``, where it has ``FEWEST``."""
    median = {}
    for index, kind in enumerate(KINDS):
        of_kind = members & (tests.kinds == index)
        if np.count_nonzero(of_kind) >= FEWEST:
            expected = _chi2_medians()[tests.rank[of_kind]]
            median[kind] = float(np.median(expected / tests.tested[of_kind]))
    return median


@functools.cache
def _chi2_medians() -> np.ndarray:
    """The median of χ²_k by k, to the largest tangent (Sim3's 7)."""
    return np.array([0.0] + [default_width(k, 0.5) ** 2 for k in range(1, 8)])


def _factors(scales: dict[str, float]) -> np.ndarray:
    """The scale of each class by its index in ``KINDS`` (1 where absent)."""
    return np.array([scales.get(kind, 1.0) for kind in KINDS])


def _by_measurement(tests: MeasurementTests, scales: dict[str, float]) -> np.ndarray:
    return _factors(scales)[tests.kinds]


def kernel_classes(graph: PoseGraph, measured: np.ndarray) -> tuple[str, ...]:
    """The classes of the measurements under a robust kernel, from its ``measured`` mask over
    the between edges, then the priors where it covers them."""
    under = np.zeros(graph.num_edges + len(graph.priors), dtype=bool)
    under[: len(measured)] = measured
    return tuple(KINDS[kind] for kind in np.unique(measurement_kinds(graph)[under]))


def scale_information(graph: PoseGraph, scales: dict[str, float]) -> None:
    """Multiplies each class's information in ``graph`` by its scale (1 where absent)."""
    weights = _factors(scales)[measurement_kinds(graph)]
    graph.edges = graph.edges.weighted(weights[: graph.num_edges])
    graph.priors = graph.priors.weighted(weights[graph.num_edges :])


def calibrate(
    graph: PoseGraph,
    first: Result,
    solve: Callable[[Result], Result],
    automatic: bool,
    robust: bool,
    covered: tuple[str, ...] = (),
    second: Callable[[Result], tuple[Result, float] | None] | None = None,
    anew: Callable[..., Result | None] | None = None,
) -> tuple[Result, Calibration | None, list[NoiseClass]]:
    """Calibrates ``graph``'s information from a solve's ``first`` result (module docstring),
    re-solving after each scaling with ``solve(last)`` from the last solution: a robust solve
    settles the decisions of the solve that ended at ``last`` and searches from them, or GNC
    runs anew after a narrowing (``_resolve``). ``robust``: the inliers are what each solve
    kept; with gross outliers among them the median scales apply, the tail scales after, and
    where a widening brings gross outliers back, calibration ends there. ``automatic``: only
    where the first solve kept gross outliers, rejected measurements that the kept ones'
    noise explains (``_consistent_rejections``; once settled, ``anew(result)`` may replace the
    result), or ``second(first)`` replaces it (``robust.second_opinion``); every class scaled
    alike, by the smallest scale of those under the kernel (``covered``). Returns the last
    result, the calibration (None where none ran), and the noise consistency of what it kept."""
    result, total, solves, classes, narrower = first, dict.fromkeys(KINDS, 1.0), 0, [], None
    consistent, present = 0, tuple(KINDS[kind] for kind in np.unique(measurement_kinds(graph)))
    stalled = widened = False  # the last scaling: changed no decision; lowered every precision
    unsearched = False  # the last result is GNC's anew, without its local search
    while True:
        checking = automatic and solves == 0
        found = _estimate_at(graph, result, robust, automatic)
        if found is None:  # no covariance: nothing to test
            break
        classes = found.classes
        consistent = _consistent_rejections(graph, found, covered) if checking else consistent
        if checking and not found.gross and not consistent:
            if second is None or (narrower := second(result)) is None:
                return result, None, classes
            (result, factor), solves = narrower, 1
            total.update(dict.fromkeys(present, factor))
            continue
        scales = _scaling(found, robust, automatic, covered, present)
        settled = all(1 / SETTLED <= s <= SETTLED for s in scales.values())
        if solves >= ROUNDS or settled or stalled or (robust and widened and found.gross):
            if unsearched:  # GNC anew at the last width: its decisions settled and searched
                (result, unsearched), solves = _resolve(graph, result, solve), solves + 1
                continue
            if not consistent or anew is None or (fresh := anew(result)) is None:
                break
            result, solves, anew = fresh, solves + 1, None
            continue
        scale_information(graph, scales)
        total.update((kind, total[kind] * scale) for kind, scale in scales.items())
        before = kept(graph, result)
        widened = solves > 0 and not found.gross and all(scale <= 1.0 for scale in scales.values())
        narrowed = robust and all(scale > SETTLED for scale in scales.values())
        (result, unsearched), solves = _resolve(graph, result, solve, narrowed and anew), solves + 1
        stalled = robust and all(map(np.array_equal, before, kept(graph, result)))
    if automatic and solves == 0:
        return result, None, classes
    scales = {kind: total[kind] for kind in present}
    calibration = Calibration(scales, automatic, solves, narrower is not None, consistent)
    return result, calibration, classes


def _resolve(graph: PoseGraph, result: Result, solve, anew=None) -> tuple[Result, bool]:
    """The solve after a scaling, and whether it is GNC's anew without its local search: that
    (``anew(result, search=False)``) where given and its TLS objective is lower than
    ``result``'s, after a scaling that raised every precision beyond ``SETTLED`` (decisions
    settled from a run that kept false loops stay bent around them); else ``solve(result)``,
    also once the width holds after GNC anew (one solve beyond ``ROUNDS`` at most)."""
    fresh = anew(result, search=False) if anew else None
    if fresh is not None:
        return fresh, True
    graph.set_values(result.values, check=False)
    return solve(result), False


def _estimate_at(
    graph: PoseGraph, result: Result, robust: bool, automatic: bool
) -> Estimate | None:
    """The estimate at a solve's result (``calibrate``), or None where the information matrix
    has no covariance to test with."""
    inliers = kept(graph, result) if robust else (None, None)
    try:
        return estimate(graph, result.values, *inliers, majority=not automatic, solved=result)
    except (NotPositiveDefinite, np.linalg.LinAlgError):
        return None


def _consistent_rejections(graph: PoseGraph, found: Estimate, covered: tuple[str, ...]) -> int:
    """How many measurements a robust solve rejected that pass the test under the median scales
    of those it kept, where they are more than ``FALSE_SHARE`` of the measurements under the
    kernel (the classes ``covered``): its width was too narrow for the noise. Else 0."""
    under = np.isin(measurement_kinds(graph), [KINDS.index(kind) for kind in covered])
    many = max(1.0, FALSE_SHARE * np.count_nonzero(under))
    return found.consistent if found.consistent > many else 0


def _scaling(
    found: Estimate,
    robust: bool,
    automatic: bool,
    covered: tuple[str, ...],
    present: tuple[str, ...],
) -> dict[str, float]:
    """The scales to apply after ``found`` (``calibrate``): the median scales where a robust
    solve kept gross outliers, else the smaller of each class's two; automatic, for every
    class ``present``, the smallest of the classes under the kernel (the kernel's width, not
    the classes' weights), or of the others where none of those has one."""
    scales = found.median if robust and found.gross else found.scales()
    if automatic and scales:
        under_kernel = [scales[kind] for kind in covered if kind in scales]
        scales = dict.fromkeys(present, min(under_kernel or scales.values()))
    return scales


def kept(graph: PoseGraph, result: Result) -> tuple[np.ndarray, np.ndarray]:
    """The edges and priors that a solve did not reject (all, in least squares)."""
    edges = np.ones(graph.num_edges, dtype=bool)
    edges[result.summary.rejected_edges] = False
    priors = np.ones(len(graph.priors), dtype=bool)
    priors[result.summary.rejected_priors] = False
    return edges, priors


def kept_noise(graph: PoseGraph, result: Result) -> list[NoiseClass]:
    """The noise consistency of the measurements that a solve kept, at its solution."""
    return noise_consistency(_inliers(graph, *kept(graph, result)), result.values, result)


def _inliers(graph: PoseGraph, edges: np.ndarray, priors: np.ndarray) -> PoseGraph:
    """The graph of the edges and priors where the masks hold."""
    work = graph.with_edges(edges)
    work.priors = graph.priors.subset(priors)
    return work
