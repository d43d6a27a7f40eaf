"""Information matrices from standard deviations, over a group's tangent in the order of
CONVENTIONS.md: translation first, then rotation, then log-scale (Sim3)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..lie import SE2, SE3, SO2, SO3, LieGroup, Sim3

Sigmas = float | Sequence[float] | np.ndarray
"""One standard deviation for every axis of a block, or one per axis."""

_BLOCKS = {
    SO2: {"rotation": 1},
    SO3: {"rotation": 3},
    SE2: {"translation": 2, "rotation": 1},
    SE3: {"translation": 3, "rotation": 3},
    Sim3: {"translation": 3, "rotation": 3, "scale": 1},
}
"""Each group's tangent blocks, in tangent order, and their sizes."""


def information_from_sigmas(
    group: type[LieGroup],
    translation: Sigmas | None = None,
    rotation: Sigmas | None = None,
    scale: float | None = None,
) -> np.ndarray:
    """The diagonal (dof, dof) information diag(1/σ²) of independent noise on each tangent
    axis: ``translation`` in the map's unit, ``rotation`` in radians, ``scale`` of log s (Sim3).
    Each block the group has must be given, and every σ be positive and finite; for example
    ``information_from_sigmas(SE3, 0.05, np.radians(1))``."""
    if group not in _BLOCKS:
        raise ValueError(f"no standard deviations for {group.__name__}")
    given = {"translation": translation, "rotation": rotation, "scale": scale}
    sigmas = []
    for block, size in _BLOCKS[group].items():
        if given[block] is None:
            raise ValueError(f"{group.__name__} needs the {block} standard deviation")
        values = np.broadcast_to(np.asarray(given[block], dtype=float), (size,))
        if not (np.isfinite(values).all() and (values > 0).all()):
            raise ValueError(f"the {block} standard deviations must be positive: {values}")
        sigmas.append(values)
    extra = [
        block for block, value in given.items() if value is not None and block not in _BLOCKS[group]
    ]
    if extra:
        raise ValueError(f"{group.__name__} has no {extra[0]} in its tangent")
    return np.diag(np.concatenate(sigmas) ** -2.0)
