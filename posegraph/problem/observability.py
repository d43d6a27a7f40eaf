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

Over the whole graph (``undetermined_direction``): at given values, a direction δ of the free
nodes that changes no residual to first order, J₀ δ = 0 on every measured direction, with the
Jacobians of every residual taken as met (jr⁻¹ = I: ∂r/∂δᵢ = −Ad(Xⱼ⁻¹ Xᵢ), ∂r/∂δⱼ = I). A rigid
motion of a part of the map that no measurement sees is one, exactly, at any values. They are
found by factorising H₁ = Σ J₀ᵀ Πₑ J₀, Πₑ the projector onto the directions that edge e's
information measures: unit weights, so that how much each edge measures (information that
spans 1e20 to 100, say) does not condition the test, only what it measures. Where every node is
tied to a held node or to a prior of full rank by edges of full rank, there is none, and nothing
is factorised: along such an edge J₀ δ = 0 gives δⱼ = Ad(Xⱼ⁻¹ Xᵢ) δᵢ, and δ = 0 at the held
node or the prior.
"""

from __future__ import annotations

import numpy as np

from ..graph import PoseGraph, named_nodes, start_information
from ..lie import LieGroup
from .cholesky import NotPositiveDefinite
from .factors import Linearization, between_jacobians, relative_poses
from .linear import NormalEquations

SINGULAR = 1e-12
"""A node block's eigenvalue at most this times its largest is a direction not measured (the
doctor's test of a singular information matrix)."""

UNDETERMINED = 1e-10
"""A column of H₁ (module docstring) whose pivot is at most this share of its diagonal entry
completes a direction that nothing measures. Measured: the smallest share on the 12 benchmark
graphs is 4e-6 at their optima (MIT, parking-garage) and 2e-7 at their files' values (w10000,
as ``posegraph info`` tests them). Where two SE3 or Sim3 maps joined by two position-only
edges can turn about them (32 random cases), H₁ did not factorise in 19 (CHOLMOD) and 17
(SuperLU), and the least share was at most 6e-14 and 4e-13 in the others."""

MOVES = 1e-6
"""A node moves along an undetermined direction where its part of it is above this share of
the largest node's."""


def node_information(graph: PoseGraph) -> np.ndarray:
    """(n, d, d) diagonal blocks of H of every node at zero residuals (module docstring)."""
    d, edges, priors = graph.group.dof, graph.edges, graph.priors
    nodes = np.concatenate([edges.i, edges.j, priors.i])
    blocks = np.concatenate(
        [
            start_information(edges.measurements, edges.information),
            edges.information,
            priors.information,
        ]
    )
    summed = np.zeros((graph.num_nodes, d, d))
    np.add.at(summed, nodes, blocks)
    return summed


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


def _measured_projector(information: np.ndarray) -> np.ndarray:
    """Πₑ of each (d, d) information matrix: the projector onto the directions it measures
    (eigenvalues above ``SINGULAR`` times its largest); zero for zero information."""
    eigenvalues, eigenvectors = np.linalg.eigh(information)
    measured = ~_unmeasured(eigenvalues)
    return (eigenvectors * measured[..., None, :]) @ np.swapaxes(eigenvectors, -1, -2)


def first_order_information(
    graph: PoseGraph, values: LieGroup, system: NormalEquations
) -> np.ndarray:
    """The CSC data of H₁ = Σ J₀ᵀ Πₑ J₀ (module docstring) at ``values``, in ``system``."""
    d, edges, priors = graph.group.dof, graph.edges, graph.priors
    met = np.zeros((len(edges), d))
    between = Linearization(met, between_jacobians(relative_poses(values, edges), met))
    unit = np.broadcast_to(np.eye(d), (len(priors), d, d))
    at_priors = Linearization(np.zeros((len(priors), d)), unit)
    data = system.normal_matrix(
        between,
        _measured_projector(edges.information),
        at_priors,
        _measured_projector(priors.information),
    )
    return data


def tied_by_full_rank(graph: PoseGraph) -> bool:
    """Whether every node is joined to a held node (``PoseGraph.gauge_nodes``) or to a node
    with a prior of full rank by edges whose information is of full rank: then no direction of
    the free nodes is undetermined (module docstring)."""
    full = ~_unmeasured(np.linalg.eigvalsh(graph.edges.information)).any(axis=1)
    full_priors = ~_unmeasured(np.linalg.eigvalsh(graph.priors.information)).any(axis=1)
    labels = graph.with_edges(full).components()
    anchored = np.zeros(labels.max(initial=-1) + 1, dtype=bool)
    anchored[labels[graph.gauge_nodes()]] = True
    anchored[labels[graph.priors.i[full_priors]]] = True
    return bool(anchored.all())


def undetermined_direction(
    graph: PoseGraph, values: LieGroup, linear_solver: str = "auto"
) -> np.ndarray | None:
    """A direction in which the free nodes can move at ``values`` without changing any residual
    to first order (module docstring), as (n, d) tangents with largest entry 1 (zero on held
    nodes), or None if there is none. In the factorisation of H₁, the column of least pivot
    share completes such a direction if its share is at most ``UNDETERMINED``, or if H₁ does
    not factorise (then H₁ plus the least ridge that does is: ``factorize_regularized``); the
    direction is found by inverse iteration from that unit column. None also if no ridge
    factorises it (as information that is not positive semi-definite can make it), or if H₁
    overflows at ``values`` (a pose too large for double precision), where nothing is told,
    and without factorising where the graph is ``tied_by_full_rank``."""
    if tied_by_full_rank(graph):
        return None
    system = NormalEquations(graph, graph.gauge_nodes(), linear_solver)
    if system.size == 0:
        return None
    data = first_order_information(graph, values, system)
    if not np.isfinite(data).all():
        return None
    try:
        ridge = system.factorize_regularized(data)
    except NotPositiveDefinite:
        return None
    share = system.pivot_shares(data)
    column = int(np.argmin(share))
    if ridge == 0.0 and share[column] > UNDETERMINED:
        return None
    unit = np.zeros(system.size)
    unit[column] = 1.0
    # Inverse iteration from that column, two solves: each shrinks the other directions' parts
    # against this one's by the ratio of its eigenvalue (near zero) to theirs. After one, the
    # tests' directions changed residuals by up to 3e-11 of a generic one; after two, 1e-15.
    direction = system.solve(system.ridge_scale(data) * system.solve(unit))
    direction = system.scatter(direction)
    return direction / np.abs(direction).max()


def describe_moving(graph: PoseGraph, direction: np.ndarray, shown: int = 3) -> str:
    """What an undetermined direction (n, d) is, naming the nodes it moves (``MOVES``): "nodes
    4, 6, 8, … (20 nodes) move together without changing any residual to first order, …"."""
    size = np.abs(direction).max(axis=1)
    nodes = graph.node_ids[size > MOVES * size.max()]
    who = named_nodes(nodes, shown) + (" moves" if nodes.size == 1 else " move together")
    return (
        f"{who} without changing any residual to first order, as a part of a map joined to the"
        " rest only by position-only edges can turn about them"
    )


def singular_information(
    graph: PoseGraph, values: LieGroup | None = None, direction: np.ndarray | None = None
) -> NotPositiveDefinite:
    """The error for a singular H: it names the first nodes with directions that no measurement
    reaches (``unmeasured_directions``), or else the nodes that an undetermined ``direction``
    moves (if not given, one found at the ``values``: ``undetermined_direction``), or else the
    common cause."""
    counts = unmeasured_directions(graph)
    if direction is None and not counts.any() and values is not None:
        direction = undetermined_direction(graph, values)
    if counts.any():
        where = describe_unmeasured(graph, counts)
    elif direction is not None:
        where = describe_moving(graph, direction)
    else:
        where = (
            "such as the rotation of a map held only by position priors, or of a part of it"
            " joined to the rest only by position-only edges"
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
