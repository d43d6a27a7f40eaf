"""Marginal covariances as text, one line per node: its id, then the upper triangle (row-major)
of its d × d covariance over the tangent of the right perturbation X · Exp(δ), in the order of
CONVENTIONS.md. Comment lines (#) name the group and the columns; ``numpy.loadtxt`` reads it.
"""

from __future__ import annotations

import numpy as np

from .atomic import atomic_write_text
from .parsing import paused_garbage_collection, upper_from_symmetric
from .writer import number_fields

TANGENT_NAMES = {
    "SE2": ("x", "y", "theta"),
    "SE3": ("rho_x", "rho_y", "rho_z", "phi_x", "phi_y", "phi_z"),
    "Sim3": ("rho_x", "rho_y", "rho_z", "phi_x", "phi_y", "phi_z", "sigma"),
}
"""Tangent coordinates by group: translation ρ, rotation φ (rad), σ = log scale."""


@paused_garbage_collection()
def format_covariances(group: str, node_ids: np.ndarray, covariances: np.ndarray) -> str:
    """The text of (k, d, d) covariances of nodes ``node_ids`` of a ``group`` ("SE2", …)."""
    names = TANGENT_NAMES[group]
    rows, columns = np.triu_indices(len(names))
    header = [
        f"# posegraph marginal covariances, {group}: tangent delta = ({', '.join(names)}) of "
        "X * Exp(delta); held nodes have zero covariance",
        "# id " + " ".join(f"{names[a]}*{names[b]}" for a, b in zip(rows, columns, strict=True)),
    ]
    values = number_fields(upper_from_symmetric(covariances))
    lines = [
        " ".join([str(node), *numbers])
        for node, numbers in zip(np.asarray(node_ids).tolist(), values, strict=True)
    ]
    return "\n".join(header + lines) + "\n"


def write_covariances(path: str, group: str, node_ids: np.ndarray, covariances: np.ndarray) -> None:
    """Write ``format_covariances`` to ``path`` atomically."""
    atomic_write_text(path, format_covariances(group, node_ids, covariances))
