"""Marginal covariances as text, written and read back, one line per node: its id, then the upper triangle (row-major)
of its d × d covariance over the tangent of the right perturbation X · Exp(δ), in the order of
CONVENTIONS.md. Comment lines (#) name the group and the columns; ``numpy.loadtxt`` reads it.
"""

from __future__ import annotations

import numpy as np

from .atomic import atomic_write_text
from .errors import GraphFileError
from .parsing import (
    LineChecker,
    paused_garbage_collection,
    read_lines,
    symmetric_from_upper,
    to_rows,
    upper_from_symmetric,
)
from .writer import number_fields, written_finite

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
    """Write ``format_covariances`` to ``path`` atomically (not if a number is NaN or ∞)."""
    with written_finite(path):
        text = format_covariances(group, node_ids, covariances)
    atomic_write_text(path, text)


GROUP_OF_WIDTH = {1 + len(n) * (len(n) + 1) // 2: group for group, n in TANGENT_NAMES.items()}
"""The group of a covariance line by its count of numbers: the id and an upper triangle."""


def read_covariances(path: str) -> tuple[str, np.ndarray, np.ndarray]:
    """(group, node ids, (k, d, d) covariances) of a file that ``write_covariances`` wrote,
    the group told by the lines' width. Raises ``GraphFileError`` naming ``file:line``: a line
    of another width, a number outside the format, an id given twice, or a matrix that is not
    positive semi-definite (λ_min < −1e-9 max|Σ|; a held node's zero is one)."""
    lines = read_lines(path)
    if not lines:
        raise GraphFileError(path, None, "holds no covariances")
    checker = LineChecker(path, lenient=False)
    entries = [(number, " ".join(tokens)) for number, tokens in lines]
    rows = to_rows("covariance", entries, tuple(GROUP_OF_WIDTH), (0,), checker)
    checker.raise_first()
    group = GROUP_OF_WIDTH[rows.numbers.shape[1]]
    size = len(TANGENT_NAMES[group])
    covariances = symmetric_from_upper(rows.numbers[:, 1:], size)
    _, first = np.unique(rows.ids(0), return_index=True)
    again = np.setdiff1d(np.arange(len(rows)), first)
    checker.keep_good(rows, np.isin(np.arange(len(rows)), again), lambda k: "node id given again")
    scale = np.abs(covariances).max(axis=(1, 2))
    smallest = np.linalg.eigvalsh(covariances)[:, 0]
    checker.keep_good(
        rows,
        smallest < -1e-9 * scale,
        lambda k: f"the covariance is not positive semi-definite (λ_min = {smallest[k]:.3g})",
    )
    checker.raise_first()
    return group, rows.ids(0).copy(), covariances
