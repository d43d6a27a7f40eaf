"""``certify``: SE-Sync's verification of a pose graph's estimate, and its Riemannian staircase
where the check fails (Rosen et al. 2019, Algorithm 1 and §4.1.3)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..graph import PoseGraph
from ..lie import LieGroup
from .data import SESyncData, sesync_data
from .stiefel import lifted, retract
from .trust_region import Minimum, minimize
from .verification import Spectrum, check, rounded

RELATIVE_TOLERANCE = 1e-6
"""δ = this × the largest diagonal entry of L(G̃ρ) + T Ω Tᵀ: λ_min(S) ≥ −δ certifies."""
GRADIENT_TOLERANCE = 1e-2
"""The trust region stops where ‖grad F‖ ≤ this × δ: well inside the check's tolerance (at a
point short of critical, S Yᵀ is of the order of the gradient)."""
MAX_RANK = 10
"""The staircase's highest rank before it gives up (SE-Sync's default)."""


@dataclasses.dataclass(frozen=True)
class Certificate:
    """The verdict on SE-Sync's problem of a graph (``data.sesync_data``: each edge's isotropic
    precisions): the estimate the check ran on (values, one per node, pose 0's translation at
    the origin), F there, λ_min(S) and the tolerance δ, whether λ_min ≥ −δ (certified globally
    optimal for that problem), the relaxation's lower bound tr(Λ) + dn·min(λ_min, −δ) on F
    (Λ + min(λ_min, −δ) I is feasible for the dual), the staircase's highest rank, and
    seconds. Where certified, λ_min(S) lies between −δ and ``smallest_eigenvalue``."""

    values: LieGroup
    objective: float
    smallest_eigenvalue: float
    tolerance: float
    certified: bool
    lower_bound: float
    rank: int
    gradient_norm: float
    time: float
    steps: tuple[dict, ...] = ()
    """Each check on the way: the rank, F at the critical point found, λ_min(S) there (as
    ``Certificate.smallest_eigenvalue``) and whether it passed."""

    def as_dict(self) -> dict:
        """A JSON-ready dictionary (without the values)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        del fields["values"]
        fields["steps"] = [dict(step) for step in self.steps]
        return {"verdict": "certified" if self.certified else "not certified", **fields}


def certify(
    graph: PoseGraph, values: LieGroup | None = None, max_rank: int = MAX_RANK
) -> Certificate:
    """Solve SE-Sync's problem of ``graph`` (an SE2 or SE3 graph without priors, connected) from
    the rotations of ``values`` (the graph's values by default) to a critical point, check the
    certificate, and where it fails climb the Riemannian staircase: lift to rank r + 1 along
    the eigenvector of λ_min(S), descend, and check again, up to ``max_rank``; the solution is
    rounded to rank d, refined and checked there."""
    began = time.perf_counter()
    data = sesync_data(graph)
    d = data.d
    matrices = (graph.values if values is None else values).as_matrix()
    y = matrices[:, :d, :d].transpose(1, 0, 2).reshape(d, -1)
    tolerance = RELATIVE_TOLERANCE * data.scale
    steps = []

    def checked(start: np.ndarray) -> tuple[Minimum, Spectrum]:
        found = minimize(data, start, GRADIENT_TOLERANCE * tolerance)
        result = check(data, found.y, tolerance)
        steps.append(
            {
                "rank": found.y.shape[0],
                "objective": found.objective,
                "smallest_eigenvalue": result.smallest,
                "certified": result.certified,
            }
        )
        return found, result

    found, result = checked(y)
    while not result.certified and found.y.shape[0] < max_rank:
        found, result = checked(_escape(data, found.y, result))
    if found.y.shape[0] > d:
        found, result = checked(rounded(found.y, d))
    bound = found.objective + data.d * data.n * min(result.smallest, -tolerance)
    return Certificate(
        _poses(graph, data, found.y),
        found.objective,
        result.smallest,
        tolerance,
        result.certified,
        bound,
        max(step["rank"] for step in steps),
        found.gradient_norm,
        time.perf_counter() - began,
        tuple(steps),
    )


def _escape(data: SESyncData, y: np.ndarray, check: Spectrum) -> np.ndarray:
    """Y lifted to rank r + 1 and moved along the eigenvector v of λ_min(S) < 0 placed in the
    new row, a direction of negative curvature (SE-Sync §4.1.3), by the longest step of
    1, ½, ¼, … that lowers F."""
    up = lifted(y)
    direction = np.zeros_like(up)
    direction[-1] = check.vector / np.linalg.norm(check.vector) * np.sqrt(data.n)
    value = data.objective(up)
    for halvings in range(40):
        moved = retract(up, direction * 0.5**halvings, data.d)
        if data.objective(moved) < value:
            return moved
    return retract(up, direction * 0.5**40, data.d)


def _poses(graph: PoseGraph, data: SESyncData, y: np.ndarray) -> LieGroup:
    """The graph's group elements from rotations Y (d × dn) and the translations that go with
    them (pose 0's at the origin)."""
    d, n = data.d, data.n
    rotations = y.reshape(d, n, d).transpose(1, 0, 2)
    matrices = np.zeros((n, d + 1, d + 1))
    matrices[:, :d, :d] = rotations
    matrices[:, :d, d] = data.recover_translations(y)
    matrices[:, d, d] = 1.0
    return graph.group.from_matrix(matrices)
