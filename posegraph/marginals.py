"""Marginal covariances of chosen nodes from the sparse factorisation of the information matrix.

At the estimate X̂, the Gaussian approximation of the posterior has information H = Σ Jᵀ Ω J over
the free nodes' tangents, with right perturbation X = X̂ · Exp(δ) (CONVENTIONS.md). The
covariance blocks of chosen nodes are blocks of H⁻¹, obtained from one sparse Cholesky
factorisation and one solve with the columns of those nodes as right-hand sides (never a dense
inverse). Held nodes (the gauge) have zero covariance: everything is relative to them, as in
gtsam with a tight prior on the gauge node.
"""

from __future__ import annotations

import numpy as np

from .graph import PoseGraph
from .lie import LieGroup
from .linear import factorized_information


def marginals(
    graph: PoseGraph,
    nodes,
    values: LieGroup | None = None,
    joint: bool = False,
    linear_solver: str = "auto",
) -> np.ndarray:
    """Covariances of ``nodes`` (ids) at ``values`` (default: the graph's current values, which
    ``posegraph.optimize`` leaves at the optimum).

    Returns (k, d, d) marginal blocks, or with ``joint=True`` the (k·d, k·d) joint covariance of
    the nodes together (for a pair, the 2d × 2d matrix with their cross-covariance).
    """
    values = graph.values if values is None else values
    index = graph.index(nodes)
    d = graph.group.dof
    system, _ = factorized_information(graph, values, linear_solver, for_covariance=True)

    blocks = system.block_of[index]
    free = np.flatnonzero(blocks >= 0)
    columns = [blocks[k] * d + np.arange(d) for k in free]
    if joint:
        covariance = np.zeros((index.size * d, index.size * d))
        if free.size:
            slots = (free[:, None] * d + np.arange(d)).ravel()
            covariance[np.ix_(slots, slots)] = system.cholesky.covariance_blocks(
                [np.concatenate(columns)]
            )[0]
        return covariance
    covariance = np.zeros((index.size, d, d))
    if free.size:
        covariance[free] = np.stack(system.cholesky.covariance_blocks(columns))
    return covariance
