"""The graph's residuals, cost and Jacobians at some values, as the solver needs them: the
Jacobians only once a step is accepted, and the linearisation of appended edges reused."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..graph import PoseGraph
from ..lie import LieGroup
from .factors import (
    Linearization,
    between_jacobians,
    linearize_priors,
    relative_poses,
    residuals_of,
    weighted_squares,
)

if TYPE_CHECKING:
    from .linear import NormalEquations


class EdgeWeighting(Protocol):
    """Turns the between edges' s = rᵀΩr into their costs ρ(s) and IRLS weights ρ′(s)."""

    def cost_and_weights(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


class Linearized:
    """Residuals and error ½ (Σ ρ(s) + Σ s_prior) of the whole graph at some values, the between
    edges' information weighted for IRLS, and their Jacobians (``between``, computed on first
    use: a rejected step never needs them).

    ``previous``, a linearisation of this graph before edges were appended, is reused for its
    edges if their nodes still have the values it was taken at (a warm start).

    ``normal_matrix`` is H's CSC data at these values once the solver has assembled it (None
    before, and where the run ended on a Newton decrement without needing it), which covariances
    at the solution reuse (``normal_matrix_for``).
    """

    def __init__(
        self,
        graph: PoseGraph,
        values: LieGroup,
        weighting: EdgeWeighting | None,
        previous: Linearized | None = None,
    ) -> None:
        self.values, self.edges, self.prior_edges = values, graph.edges, graph.priors
        self.weighted = weighting is not None
        self.normal_matrix: np.ndarray | None = None
        reused = previous is not None and previous._holds_for(graph.edges, values)
        self.reused_edges = len(previous.edges) if reused else 0
        # Without reuse, every edge is "appended" (and the edge set is not copied).
        appended = graph.edges.subset(slice(self.reused_edges, None)) if reused else graph.edges
        self._relative = relative_poses(values, appended)
        self._residuals = residuals_of(self._relative, appended)
        self._reused = previous.between if reused else None
        squared = weighted_squares(self._residuals, appended.information)
        if reused:
            squared = np.concatenate([previous.squared, squared])
        self.squared = squared
        self.priors: Linearization = linearize_priors(values, graph.priors)
        prior_total = weighted_squares(self.priors.residuals, graph.priors.information).sum()
        if weighting is None:
            self.information = graph.edges.information
            self.error = 0.5 * float(self.squared.sum() + prior_total)
        else:
            cost, weights = weighting.cost_and_weights(self.squared)
            self.information = graph.edges.information * weights[:, None, None]
            self.error = 0.5 * float(cost.sum() + prior_total)

    @functools.cached_property
    def between(self) -> Linearization:
        """Residuals and Jacobians of every between edge."""
        jacobians = between_jacobians(self._relative, self._residuals)
        appended = Linearization(self._residuals, jacobians)
        return appended if self._reused is None else self._reused.extended(appended)

    def normal_matrix_for(
        self, graph: PoseGraph, values: LieGroup, system: NormalEquations
    ) -> np.ndarray | None:
        """H's CSC data in ``system``'s pattern (the solve's, of this linearisation) if this is
        the least-squares linearisation (no IRLS weights) of ``graph`` at exactly ``values``,
        over exactly its edges and priors: ``normal_matrix``, assembled here and kept if the
        solve did not need it; else None."""
        if self.weighted:
            return None
        same = (
            len(values) == len(self.values)
            and values.same_as(self.values)
            and len(graph.edges) == len(self.edges)
            and graph.edges.starts_with(self.edges)
            and len(graph.priors) == len(self.prior_edges)
            and graph.priors.starts_with(self.prior_edges)
        )
        return self.normal_matrix_in(system) if same else None

    def normal_matrix_in(self, system: NormalEquations) -> np.ndarray:
        """H's CSC data at these values in ``system``'s pattern: ``normal_matrix``, assembled
        on first use."""
        if self.normal_matrix is None:
            self.normal_matrix = system.normal_matrix(*self._terms())
        return self.normal_matrix

    def gradient_in(self, system: NormalEquations) -> np.ndarray:
        """The gradient Jᵀ Ω r at these values, in ``system``'s variable order."""
        return system.gradient(*self._terms())

    def _terms(self) -> tuple[Linearization, np.ndarray, Linearization, np.ndarray]:
        """What the normal equations are assembled from: the between edges' linearisation and
        (weighted) information, the priors' and theirs."""
        return self.between, self.information, self.priors, self.prior_edges.information

    def _holds_for(self, edges, values: LieGroup) -> bool:
        """Whether this linearisation is that of the first edges of ``edges`` at ``values``."""
        count = len(self.values)
        return (
            count <= len(values)
            and edges.starts_with(self.edges)
            and values[:count].same_as(self.values)
        )
