"""A second opinion at a narrower width, for a GNC run at the default width that fits the
median measurement worse than its start did, or that rejected nothing.

Where the information overstates the noise many times over, the default width spans many
times the noise, and with many false loops GNC can settle on a wrong solution that is
consistent with itself: the false loops it kept bend the map, the true loops it kept absorb
the bending within the width, and the kept residuals look like the information's noise, so the
noise check finds nothing (parking-garage with 30% false loops, its information 20,000× its
noise). Such a solution fits the median loop closure worse than dead reckoning does, which a
solution with fewer than half its loops false never should: the least median of squares
criterion (Rousseeuw 1984, "Least Median of Squares Regression") is what tells them apart.
GNC then runs again from the same start with every precision ``NARROWER`` times higher, and
its solution replaces the first where it has the lower TLS objective at the file's
information (calibration then scales the information from there).

A run that rejected nothing may have crumpled the map to fit every false loop within a width
far wider than the noise (w10000 with 30% false loops: its information states 73× the
residuals' variance). Its median loop closure fits better than dead reckoning, and at the
file's information its TLS objective is lower than that of the true map, which pays c² for
each false loop; but the true map fits the median loop closure far better. There the narrower
run's solution replaces the first where its median loop closure's s is more than ``OFF_BY``
times lower (on files without outliers, it is at most a few per cent lower, or higher). The
median is read after the narrower run's graduated stages, before its local search, which runs
only where the run is taken: a search refines a few decisions and does not move the median
loop tenfold, and on files without outliers, which every robust run there asks, it would be
most of the run's time.

Where GNC's first width was too narrow instead (it rejected true loops that the noise of what
it kept explains, ``calibration``), the decisions that calibration settles from that run at the
wider width can stay bent around the true loops it rejected: GNC then runs anew from the start
at the calibrated width, and its solution replaces the settled one where its TLS objective is
lower."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..graph import PoseGraph
from ..lie import LieGroup
from ..problem.factors import between_squares
from ..solvers import Result
from .calibration import scale_information
from .noise import KINDS, OFF_BY
from .run import cost
from .spec import Kernel

NARROWER = 100.0
"""The factor of every precision in the second opinion: its width is a tenth of the first's
in residual units."""


def fits_median_worse(
    graph: PoseGraph, measured: np.ndarray, start: LieGroup, values: LieGroup, by: float = 1.0
) -> bool:
    """Whether the median s = rᵀΩr of the ``measured`` between edges is larger at ``values``
    than ``by`` times that at ``start``."""
    if not measured.any():
        return False
    at_start = np.median(between_squares(start, graph.edges)[measured])
    return bool(np.median(between_squares(values, graph.edges)[measured]) > by * at_start)


@dataclasses.dataclass(frozen=True)
class FromStart:
    """GNC runs anew from the ``start`` of a robust call at the default width, which
    calibration asks for: ``solve(search=...)`` runs GNC from the graph's values, which these
    set to ``start``, at the graph's information as it then is, with its local search or
    without; ``solve(run)`` settles the decisions of an earlier ``run`` from the graph's values
    and searches from them."""

    graph: PoseGraph
    kernel: Kernel
    start: LieGroup
    solve: Callable[..., Result]

    def second_opinion(self, first: Result) -> tuple[Result, float] | None:
        """The narrower run's result and its precision factor where ``first``, a GNC run from
        ``start`` at the graph's information, fits the median measurement worse than
        ``start`` and the narrower run ends with a lower TLS objective at the graph's
        information, or where ``first`` rejected nothing and the narrower run's stages fit the
        median measurement ``OFF_BY`` times better (their decisions are then settled and
        searched from); the graph's information is then left multiplied by the factor. Else
        None, the graph as it was."""
        graph = self.graph
        measured = self.kernel.measured[: graph.num_edges]
        worse = fits_median_worse(graph, measured, self.start, first.values)
        summary = first.summary
        kept_all = measured.any() and not (summary.rejected_edges or summary.rejected_priors)
        if not worse and not kept_all:
            return None
        information = graph.edges, graph.priors
        scale_information(graph, dict.fromkeys(KINDS, NARROWER))
        narrower = graph.edges, graph.priors
        result = self._run(search=worse, stage="narrower")
        graph.edges, graph.priors = information
        if worse:
            better = self._objective(result.values) < self._objective(first.values)
        else:  # the median loop closure decides (least median of squares), by far
            better = fits_median_worse(graph, measured, result.values, first.values, OFF_BY)
        if not better:
            return None
        graph.edges, graph.priors = narrower
        if not worse:  # its decisions settled and searched from, as in GNC's own run
            graph.set_values(result.values, check=False)
            result = self.solve(result, stage="narrower")
        return result, NARROWER

    def anew(self, settled: Result, search: bool = True) -> Result | None:
        """GNC anew at the graph's information, its result where its TLS objective there is
        lower than that of ``settled``: decisions settled from a first run whose width was
        too narrow can stay bent around the true loops it rejected, and decisions settled at
        a narrower width from a run that kept false loops stay bent around them. Else None.
        Without ``search``, GNC does not search locally."""
        result = self._run(search)
        return result if self._objective(result.values) < self._objective(settled.values) else None

    def _run(self, search: bool = True, stage: str = "calibrated") -> Result:
        self.graph.set_values(self.start, check=False)
        return self.solve(search=search, stage=stage)

    def _objective(self, values: LieGroup) -> float:
        """The TLS cost that GNC minimises, at ``values``."""
        self.graph.set_values(values, check=False)
        return cost(self.graph, self.kernel)
