"""Chordal initialisation of SE2, SE3 and Sim3 pose graphs (Carlone, Tron, Daniilidis & Dellaert 2015,
"Initialization techniques for 3D SLAM: a survey on rotation estimation and its use in pose
graph optimization", §IV-B and §V).

1. Rotations: minimise Σₑ wₑ ‖Rⱼ − Rᵢ Zₑ‖²_F over unconstrained d × d matrices. Row a of that
   residual is Rⱼ[a] − Zₑᵀ Rᵢ[a], so the problem splits into d linear least-squares problems
   sharing one sparse matrix, solved with one factorisation. Each result is projected to the
   nearest rotation (SVD).
2. Sim3 only: log-scales by linear least squares, σⱼ − σᵢ = log sₑ, weighted by Ω_σσ.
3. Translations, given rotations and scales: for SE2 and SE3, minimise
   Σₑ (tⱼ − tᵢ − Rᵢ Δtₑ)ᵀ Rᵢ Ω_tt Rᵢᵀ (…), a linear least-squares problem. For Sim3, compose
   tⱼ = tᵢ + sᵢ Rᵢ Δtₑ along the spanning tree (odometry first) from the held nodes. The scales
   of step 2 come from the log-scale information alone, and least squares spread their errors
   through the map: Levenberg-Marquardt then crawled along a curved valley (a 3000-keyframe
   monocular sequence, 61 iterations; 7 from the composed translations).

Any information matrix is accepted: the rotation weight wₑ is the mean eigenvalue of the
rotation block of Ωₑ (its trace over d_rot), and the translation block Ω_tt is used whole.
Every connected component is anchored (fixed nodes, a prior's measurement, or its lowest id at
its current value), so disconnected graphs and degree-1 nodes need no special care. A node that
no edge weighs in one of the three problems (its rotation, say, seen only by position-only
edges) has a zero row in that system, which the solve's ridge
(``BlockPattern.factorize_regularized``) leaves at zero; it keeps the graph's value there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import PoseGraph
from ..lie import SE2, SE3, LieGroup, Sim3
from ..lie.so3 import project_to_rotation
from ..problem.linear import BlockPattern
from ..problem.pattern import free_block_index
from .spanning_tree import spanning_tree


def supports(group: type[LieGroup]) -> bool:
    return group in (SE2, SE3, Sim3)


def _split(group: type[LieGroup], values: LieGroup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rotation matrices, translations, scales) of SE2, SE3 or Sim3 elements."""
    if group is SE2:
        return values.rotation_matrix, values.translation, np.ones(values.batch_shape)
    scale = values.scale if group is Sim3 else np.ones(values.batch_shape)
    return values.rotation, values.translation, scale


def _blocks(group: type[LieGroup], information: np.ndarray):
    """(rotation weights (m,), translation information (m, d, d), log-scale weights (m,)) of
    (ρ, φ[, σ])-ordered information matrices."""
    d = 2 if group is SE2 else 3
    rotation = information[
        :, d : 2 * d if group is Sim3 else None, d : 2 * d if group is Sim3 else None
    ]
    weights = np.trace(rotation, axis1=1, axis2=2) / rotation.shape[1]
    scale_weights = information[:, -1, -1] if group is Sim3 else np.zeros(len(information))
    return weights, information[:, :d, :d], scale_weights


def _anchors(graph: PoseGraph) -> tuple[np.ndarray, LieGroup]:
    """One held node per component at least: the gauge nodes at their values, plus a node of
    every component that only has priors, at its prior's measurement."""
    gauge = graph.gauge_nodes()
    prior_labels = graph.components()[graph.priors.i]
    candidates = np.flatnonzero(graph.components_set_by_priors()[prior_labels])
    first = np.sort(candidates[np.unique(prior_labels[candidates], return_index=True)[1]])
    held = np.concatenate([gauge, graph.priors.i[first]])
    values = graph.group.concatenate([graph.values[gauge], graph.priors.measurements[first]])
    return held, values


def _solve(
    pattern: BlockPattern, diagonal: np.ndarray, off_diagonal: np.ndarray, pieces: np.ndarray
) -> np.ndarray:
    """Minimise Σₑ ‖Jₑ x + r⁰ₑ‖²_W over the free blocks: H x = −g, where edge e adds
    ``diagonal`` (m, d, d) to H_ii and H_jj, ``off_diagonal`` (m, d, d) to H_ij (its transpose
    to H_ji), and g's i and j parts ``pieces`` (m, 2, d, k), one right-hand side per trailing
    column, all solved with one factorisation. Returns (n, d, k) with zeros at held nodes."""
    blocks = np.stack(
        [
            np.concatenate([diagonal, off_diagonal], axis=2),
            np.concatenate([np.swapaxes(off_diagonal, 1, 2), diagonal], axis=2),
        ],
        axis=1,
    )
    pattern.factorize_regularized(pattern.matrix_data(blocks))
    columns = pieces.shape[3]
    rhs = np.stack([pattern.vector(pieces[..., c]) for c in range(columns)], axis=1)
    return pattern.scatter(pattern.solve(-rhs))


def _composed_translations(
    graph: PoseGraph, held: np.ndarray, translation: np.ndarray, steps: np.ndarray
) -> np.ndarray:
    """Translations composed along the spanning tree from the held nodes' ``translation``
    (n, d): each child's is its parent's plus the ``steps`` tⱼ − tᵢ (m, d) of its tree edge
    i → j, or minus them where the edge runs from the child."""
    n = graph.num_nodes
    known = np.zeros(n, dtype=bool)
    known[held] = True
    tree = spanning_tree(graph, known)
    offsets = np.zeros((n + 1, translation.shape[1]))
    offsets[held] = translation[held]
    along = steps[tree.edge]
    offsets[tree.children] = np.where(tree.reversed[:, None], -along, along)
    return tree.accumulated(offsets, np.add)[:n]


@dataclasses.dataclass(frozen=True)
class _Relaxation:
    """What the three linear stages of ``chordal_values`` share: the edges' ends, the held
    nodes, and the block pattern of the free ones."""

    n: int
    i: np.ndarray
    j: np.ndarray
    held: np.ndarray
    block_of: np.ndarray
    _patterns: dict = dataclasses.field(default_factory=dict)

    def pattern(self, d: int) -> BlockPattern:
        """The block pattern of d × d blocks, analysed once (rotations and translations share
        it where their blocks are of one size)."""
        if d not in self._patterns:
            no_priors = np.zeros(0, dtype=np.int64)
            self._patterns[d] = BlockPattern(self.block_of, self.i, self.j, no_priors, d)
        return self._patterns[d]

    def kept(self, solved: np.ndarray, start: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """``solved`` (n, …), but ``start`` at the free nodes that no edge weighs (``weights``
        (m,) ≥ 0, per edge)."""
        n = self.n
        unweighted = np.bincount(self.i, weights, n) + np.bincount(self.j, weights, n) == 0
        unweighted[self.held] = False
        return np.where(unweighted.reshape((n,) + (1,) * (solved.ndim - 1)), start, solved)


def chordal_values(graph: PoseGraph) -> LieGroup:
    """Initial values of an SE2, SE3 or Sim3 graph by chordal relaxation (module docstring)."""
    group = graph.group
    if not supports(group):
        raise ValueError(
            f"chordal initialisation handles SE2, SE3 and Sim3 graphs, not {group.__name__}"
        )
    edges = graph.edges
    z, measured_translation, measured_scale = _split(group, edges.measurements)
    weight, translation_information, scale_weight = _blocks(group, edges.information)
    held, held_values = _anchors(graph)
    held_rotation, held_translation, held_scale = _split(group, held_values)
    start_rotation, start_translation, start_scale = _split(group, graph.values)
    n = graph.num_nodes
    relaxation = _Relaxation(n, edges.i, edges.j, held, free_block_index(n, held))
    rotation = _rotations(relaxation, z, weight, held_rotation, start_rotation)
    scale = np.ones(n)
    if group is Sim3:
        scale = _scales(relaxation, measured_scale, scale_weight, held_scale, start_scale)
    i = edges.i
    # Translations: tⱼ − tᵢ = sᵢ Rᵢ Δt of every edge (the between residual's translation is
    # Rᵢᵀ (tⱼ − tᵢ)/sᵢ − Δt).
    steps = scale[i, None] * np.einsum("mab,mb->ma", rotation[i], measured_translation)
    translation = np.zeros((n, rotation.shape[-1]))
    translation[held] = held_translation
    if group is Sim3:
        translation = _composed_translations(graph, held, translation, steps)
    else:
        translation = _translations(
            relaxation, rotation, translation_information, translation, steps
        )
    translation_weight = np.trace(translation_information, axis1=1, axis2=2)
    translation = relaxation.kept(translation, start_translation, translation_weight)
    if group is SE2:
        return SE2(np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0]), translation)
    if group is Sim3:
        return Sim3(rotation, translation, scale)
    return SE3(rotation, translation)


def _rotations(relaxation: _Relaxation, z, weight, held_rotation, start_rotation) -> np.ndarray:
    """Rotations, row by row: r = Rⱼ[a] − Zᵀ Rᵢ[a], so Jᵢ = −Zᵀ, Jⱼ = I and, Z being orthogonal,
    H_ii = H_jj = w I, H_ij = −w Z, projected onto the rotations. Known rows of held nodes enter
    through r⁰."""
    i, j, held, d = relaxation.i, relaxation.j, relaxation.held, z.shape[-1]
    w = weight[:, None, None]
    rows = np.zeros((relaxation.n, d, d))
    rows[held] = held_rotation
    r0 = rows[j] - rows[i] @ z  # (m, a, ·): row a of every edge's residual at the known rows
    pieces = np.stack([-w * (z @ np.swapaxes(r0, 1, 2)), w * np.swapaxes(r0, 1, 2)], axis=1)
    rows += np.swapaxes(_solve(relaxation.pattern(d), w * np.eye(d), -w * z, pieces), 1, 2)
    rotation = relaxation.kept(project_to_rotation(rows), start_rotation, weight)
    rotation[held] = held_rotation
    return rotation


def _scales(relaxation: _Relaxation, measured_scale, scale_weight, held_scale, start_scale):
    """Scales (Sim3): r = σⱼ − σᵢ − log sₑ, weighted by the σσ information (1 × 1 blocks)."""
    i, j = relaxation.i, relaxation.j
    log_scale = np.zeros(relaxation.n)
    log_scale[relaxation.held] = np.log(held_scale)
    w_s = scale_weight[:, None, None]
    r0 = (log_scale[j] - log_scale[i] - np.log(measured_scale))[:, None, None]
    pieces = np.stack([-w_s * r0, w_s * r0], axis=1)
    log_scale += _solve(relaxation.pattern(1), w_s, -w_s, pieces)[:, 0, 0]
    return np.exp(relaxation.kept(log_scale, np.log(start_scale), scale_weight))


def _translations(relaxation: _Relaxation, rotation, information, translation, steps):
    """Translations by least squares: r = tⱼ − tᵢ − Rᵢ Δt, weight W = Rᵢ Ω_tt Rᵢᵀ; Jᵢ = −I,
    Jⱼ = I; ``translation`` holds the held nodes' values."""
    i, j = relaxation.i, relaxation.j
    world = rotation[i] @ information @ np.swapaxes(rotation[i], 1, 2)
    r0 = translation[j] - translation[i] - steps
    weighted = np.einsum("mab,mb->ma", world, r0)[:, :, None]
    pieces = np.stack([-weighted, weighted], axis=1)
    solved = _solve(relaxation.pattern(translation.shape[1]), world, -world, pieces)
    return translation + solved[:, :, 0]
