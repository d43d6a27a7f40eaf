"""gtsam's tangent order for each group (CONVENTIONS.md, "Peer conventions"), for moving
tangent vectors, covariances, information and Jacobians between posegraph and gtsam.

* SO2, SE2, SO3: the same as ours: (θ), (x, y, θ), (φ).
* SE3: gtsam's Pose3 tangent is (ω, v); ours is (ρ, φ) = (v, ω).
* Sim3: gtsam's Similarity3 tangent is (ω, u, λ); ours is (ρ, φ, σ) = (u, ω, λ).
"""

from __future__ import annotations

import numpy as np

from .base import LieGroup
from .se2 import SE2
from .se3 import SE3
from .sim3 import Sim3
from .so2 import SO2
from .so3 import SO3

_TANGENT_ORDER = {
    SO2: np.arange(1),
    SE2: np.arange(3),
    SO3: np.arange(3),
    SE3: np.array([3, 4, 5, 0, 1, 2]),
    Sim3: np.array([3, 4, 5, 0, 1, 2, 6]),
}
"""Index k of gtsam's tangent holds our component _TANGENT_ORDER[group][k]."""


def tangent_permutation(group: type[LieGroup]) -> np.ndarray:
    """P with ``ξ_gtsam = P ξ_ours``; a covariance or information maps as P Σ Pᵀ."""
    return np.eye(group.dof)[_TANGENT_ORDER[group]]


def tangent_to_gtsam(group: type[LieGroup], tangent: np.ndarray) -> np.ndarray:
    """(…, dof) tangent vectors in gtsam's order."""
    return np.asarray(tangent, float)[..., _TANGENT_ORDER[group]]


def tangent_from_gtsam(group: type[LieGroup], tangent: np.ndarray) -> np.ndarray:
    """(…, dof) tangent vectors of gtsam's order in ours."""
    return np.asarray(tangent, float)[..., np.argsort(_TANGENT_ORDER[group])]


def matrix_to_gtsam(group: type[LieGroup], matrix: np.ndarray) -> np.ndarray:
    """A (…, dof, dof) matrix over our tangent (covariance, information, Jacobian) in gtsam's."""
    p = tangent_permutation(group)
    return p @ matrix @ p.T


def matrix_from_gtsam(group: type[LieGroup], matrix: np.ndarray) -> np.ndarray:
    """A (…, dof, dof) matrix over gtsam's tangent (a ``Marginals.marginalCovariance``, say) in
    ours: ``matrix_to_gtsam`` undone."""
    p = tangent_permutation(group)
    return p.T @ matrix @ p
