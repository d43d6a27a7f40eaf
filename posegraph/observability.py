"""Directions of a node that no measurement reaches.

A node's diagonal block of H = Σ JᵀΩJ, where every measurement is met exactly (r = 0, so
jr⁻¹(r) = I): an edge i → j with measurement Z adds Ω to node j's block and
Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) to node i's (``factors``: ∂r/∂δᵢ = −jr⁻¹(r) Ad(Xⱼ⁻¹ Xᵢ), and Xⱼ⁻¹ Xᵢ = Z⁻¹
at r = 0); a prior adds Ω. A direction in which that block is singular moves the node without
changing any residual to first order: the node's value there is the initialisation's, and it
has no covariance. H being positive semi-definite, such a block makes H singular at r = 0; the
converse does not hold (two maps joined by position-only edges can turn about them). Where
residuals are not zero, the Log couples rotation and translation at second order, and H may
factorise, with variances in those directions that mean nothing (``marginals``'
``require_measured``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from .graph import PoseGraph
from .sparse_cholesky import NotPositiveDefinite

SINGULAR = 1e-12
"""A node block's eigenvalue at most this times its largest is a direction not measured (the
doctor's test of a singular information matrix)."""


def node_information(graph: PoseGraph) -> np.ndarray:
    """(n, d, d) diagonal blocks of H of every node at zero residuals (module docstring)."""
    d, edges, priors = graph.group.dof, graph.edges, graph.priors
    adjoint = edges.measurements.inverse().adjoint()
    nodes = np.concatenate([edges.i, edges.j, priors.i])
    blocks = np.concatenate(
        [
            np.swapaxes(adjoint, 1, 2) @ edges.information @ adjoint,
            edges.information,
            priors.information,
        ]
    )
    # Summed per node as a product with the (n, k) incidence matrix of the k blocks' nodes.
    incidence = scipy.sparse.csr_matrix(
        (np.ones(nodes.size), (nodes, np.arange(nodes.size))), (graph.num_nodes, nodes.size)
    )
    return (incidence @ blocks.reshape(-1, d * d)).reshape(-1, d, d)


def _unmeasured(eigenvalues: np.ndarray) -> np.ndarray:
    """Which eigenvalues of each block (ascending, along the last axis) are of directions that
    no measurement reaches."""
    return eigenvalues <= SINGULAR * eigenvalues[..., -1:]


def _counts(graph: PoseGraph, blocks: np.ndarray) -> np.ndarray:
    """How many of each node block's directions no measurement reaches (0 for held nodes: the
    gauge, ``PoseGraph.gauge_nodes``)."""
    counts = np.count_nonzero(_unmeasured(np.linalg.eigvalsh(blocks)), axis=1)
    counts[graph.gauge_nodes()] = 0
    return counts


def unmeasured_directions(graph: PoseGraph) -> np.ndarray:
    """How many of each node's d tangent directions no measurement reaches (0 for held nodes)."""
    return _counts(graph, node_information(graph))


def unmeasured_share(graph: PoseGraph) -> np.ndarray:
    """(n, d): the diagonal of the projector onto each node's directions that no measurement
    reaches, per tangent coordinate: 1 on an unmeasured axis (the rotation of a pose seen only by
    position-only edges), 0 on a measured one, between for a direction that mixes axes (0 for
    held nodes)."""
    blocks = node_information(graph)
    nodes = np.flatnonzero(_counts(graph, blocks))
    eigenvalues, eigenvectors = np.linalg.eigh(blocks[nodes])
    share = np.zeros(blocks.shape[:2])
    share[nodes] = np.einsum("nkc,nc->nk", eigenvectors**2, _unmeasured(eigenvalues))
    return share


def singular_information(graph: PoseGraph) -> NotPositiveDefinite:
    """The error for a singular H: it names the first nodes with directions that no measurement
    reaches (``unmeasured_directions``), or else gives the common cause."""
    counts = unmeasured_directions(graph)
    where = (
        describe_unmeasured(graph, counts)
        if counts.any()
        else (
            "such as the rotation of a map held only by position priors, or of a part of it"
            " joined to the rest only by position-only edges"
        )
    )
    return NotPositiveDefinite(
        "the information matrix is singular: some direction of the free nodes is measured by"
        f" nothing ({where}), so its covariance is unbounded"
    )


def describe_unmeasured(graph: PoseGraph, counts: np.ndarray, shown: int = 3) -> str:
    """The first ``shown`` nodes with unmeasured directions (``unmeasured_directions``), as
    "node 4: 3 of its 6 directions; …"."""
    nodes = np.flatnonzero(counts)
    named = "; ".join(
        f"node {graph.node_ids[k]}: {counts[k]} of its {graph.group.dof} directions"
        for k in nodes[:shown]
    )
    return named + ("; …" if nodes.size > shown else "")
