"""Chordal initialisation of SE2 and SE3 pose graphs (Carlone, Tron, Daniilidis & Dellaert 2015,
"Initialization techniques for 3D SLAM: a survey on rotation estimation and its use in pose
graph optimization", §IV-B and §V).

1. Rotations: minimise Σₑ wₑ ‖Rⱼ − Rᵢ Zₑ‖²_F over unconstrained d × d matrices. Row a of that
   residual is Rⱼ[a] − Zₑᵀ Rᵢ[a], so the problem splits into d linear least-squares problems
   sharing one sparse matrix, solved with one factorisation. Each result is projected to the
   nearest rotation (SVD).
2. Translations, given the rotations: minimise Σₑ (tⱼ − tᵢ − Rᵢ Δtₑ)ᵀ Rᵢ Ω_tt Rᵢᵀ (…), a linear
   least-squares problem.

Any information matrix is accepted: the rotation weight wₑ is the mean eigenvalue of the
rotation block of Ωₑ (its trace over d_rot), and the translation block Ω_tt is used whole.
Every connected component is anchored (fixed nodes, a prior's measurement, or its lowest id at
its current value), so disconnected graphs and degree-1 nodes need no special care.
"""

from __future__ import annotations

import numpy as np

from .graph import PoseGraph
from .lie import SE2, SE3, LieGroup
from .lie.so3 import project_to_rotation
from .linear import BlockPattern, free_block_index


def supports(group: type[LieGroup]) -> bool:
    return group in (SE2, SE3)


def _split(group: type[LieGroup], values: LieGroup) -> tuple[np.ndarray, np.ndarray]:
    """(rotation matrices, translations) of SE2 or SE3 elements."""
    if group is SE2:
        return values.rotation_matrix, values.translation
    return values.rotation, values.translation


def _blocks(group: type[LieGroup], information: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rotation weights (m,), translation information (m, d, d)) of (ρ, φ)-ordered matrices."""
    d = 2 if group is SE2 else 3
    rotation = information[:, d:, d:]
    weights = np.trace(rotation, axis1=1, axis2=2) / rotation.shape[1]
    return weights, information[:, :d, :d]


def _anchors(graph: PoseGraph) -> tuple[np.ndarray, LieGroup]:
    """One held node per component at least: the gauge nodes at their values, plus a node of
    every component that only has priors, at its prior's measurement."""
    held = graph.gauge_nodes()
    values = graph.values[held]
    if len(graph.priors):
        labels = graph.components()
        anchored = np.zeros(labels.max() + 1, dtype=bool)
        anchored[labels[held]] = True
        first_prior = {}
        for k, node in enumerate(graph.priors.i.tolist()):
            if not anchored[labels[node]] and labels[node] not in first_prior:
                first_prior[labels[node]] = k
        if first_prior:
            priors = np.array(sorted(first_prior.values()))
            held = np.concatenate([held, graph.priors.i[priors]])
            values = graph.group.concatenate([values, graph.priors.measurements[priors]])
    return held, values


def _solve(
    pattern: BlockPattern, blocks: np.ndarray, pieces: np.ndarray, num_nodes: int
) -> np.ndarray:
    """Minimise Σₑ ‖Jₑ x + r⁰ₑ‖²_W over the free blocks: H x = −g, one right-hand side per
    trailing column of ``pieces`` (2m, d, k), all with one factorisation. Returns (n, d, k)
    with zeros at held nodes."""
    pattern.factorize(pattern.matrix_data(blocks))
    columns = pieces.shape[2]
    solution = np.zeros((num_nodes, pattern.d, columns))
    free = np.flatnonzero(pattern.block_of >= 0)
    for c in range(columns):
        x = pattern.solve(-pattern.vector(np.ascontiguousarray(pieces[:, :, c])))
        solution[free, :, c] = x.reshape(-1, pattern.d)
    return solution


def chordal_values(graph: PoseGraph) -> LieGroup:
    """Initial values of an SE2 or SE3 graph by chordal relaxation (module docstring)."""
    group = graph.group
    if not supports(group):
        raise ValueError(f"chordal initialisation handles SE2 and SE3 graphs, not {group.__name__}")
    n, d = graph.num_nodes, 2 if group is SE2 else 3
    edges = graph.edges
    i, j = edges.i, edges.j
    z, measured_translation = _split(group, edges.measurements)
    weight, translation_information = _blocks(group, edges.information)
    held, held_values = _anchors(graph)
    held_rotation, held_translation = _split(group, held_values)
    pattern = BlockPattern(free_block_index(n, held), i, j, np.zeros(0, dtype=np.int64), d)
    w = weight[:, None, None]
    eye = np.eye(d)

    # Rotations, row by row: r = Rⱼ[a] − Zᵀ Rᵢ[a], so Jᵢ = −Zᵀ, Jⱼ = I and, Z being orthogonal,
    # H_ii = H_jj = w I, H_ij = −w Z. Known rows of held nodes enter through r⁰.
    rows = np.zeros((n, d, d))
    rows[held] = held_rotation
    r0 = rows[j] - rows[i] @ z  # (m, a, ·): row a of every edge's residual at the known rows
    blocks = np.concatenate([w * eye, w * eye, -w * z, -w * np.swapaxes(z, 1, 2)])
    pieces = np.concatenate([-w * (z @ np.swapaxes(r0, 1, 2)), w * np.swapaxes(r0, 1, 2)])
    rows += np.swapaxes(_solve(pattern, blocks, pieces, n), 1, 2)
    rotation = project_to_rotation(rows)
    rotation[held] = held_rotation

    # Translations: r = tⱼ − tᵢ − Rᵢ Δt with weight W = Rᵢ Ω_tt Rᵢᵀ; Jᵢ = −I, Jⱼ = I.
    world = rotation[i] @ translation_information @ np.swapaxes(rotation[i], 1, 2)
    translation = np.zeros((n, d))
    translation[held] = held_translation
    r0 = (
        translation[j] - translation[i] - np.einsum("mab,mb->ma", rotation[i], measured_translation)
    )
    weighted = np.einsum("mab,mb->ma", world, r0)[:, :, None]
    blocks = np.concatenate([world, world, -world, -world])
    translation += _solve(pattern, blocks, np.concatenate([-weighted, weighted]), n)[:, :, 0]
    if group is SE2:
        return SE2(np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0]), translation)
    return SE3(rotation, translation)
