"""The information matrix H = Σ Jᵀ Ω J of a pose graph at some values, assembled into its
``NormalEquations`` and factorised, with a ridge or a pivot test where asked: what covariances
and leverage read."""

from __future__ import annotations

import numpy as np

from ..graph import PoseGraph
from ..lie import LieGroup
from .cholesky import NotPositiveDefinite
from .factors import Linearization, linearize_between, linearize_priors
from .linear import NormalEquations


def factorized_information(
    graph: PoseGraph,
    values: LieGroup,
    system: NormalEquations,
    regularize: bool = False,
    least_share: float = 0.0,
) -> Linearization:
    """The information matrix H = Σ Jᵀ Ω J of ``graph`` at ``values`` (priors included, gauge
    nodes held), assembled into ``system`` (normal equations of this graph's structure) and
    factorised by ``factorize_information``; returns the between edges' linearisation."""
    between = linearize_between(values, graph.edges)
    priors = linearize_priors(values, graph.priors)
    data = system.normal_matrix(between, graph.edges.information, priors, graph.priors.information)
    factorize_information(system, data, regularize, least_share)
    return between


def factorize_information(
    system: NormalEquations, data: np.ndarray, regularize: bool = False, least_share: float = 0.0
) -> None:
    """Factorise H (its CSC ``data`` in ``system``), with ``regularize`` by
    ``factorize_regularized``. With ``least_share``, a pivot of at most that share of its
    diagonal entry (``NormalEquations.pivot_shares``: H singular to working precision, which
    one backend may factorise where another fails) raises ``NotPositiveDefinite`` too."""
    (system.factorize_regularized if regularize else system.factorize)(data)
    if least_share and system.size and system.pivot_shares(data).min() <= least_share:
        raise NotPositiveDefinite(f"a pivot of at most {least_share:g} of its diagonal entry")
