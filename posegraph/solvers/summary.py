"""What an optimisation returns: the values and a summary of how it went."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..lie import LieGroup

if TYPE_CHECKING:
    from ..problem.linear import NormalEquations
    from ..problem.linearization import Linearized
    from ..robust.leverage import Leverage

PHASES = ("linearize", "assemble", "factorize", "solve", "other")
"""The phases that ``Summary.phase_times`` times."""


@dataclasses.dataclass(frozen=True)
class IterationRecord:
    """One iteration: the error after it (½ Σ rᵀΩr), λ used, the step's norm, and whether the
    step was accepted."""

    iteration: int
    error: float
    damping: float
    step_norm: float
    accepted: bool
    elapsed: float
    """Seconds since the start of ``optimize``."""
    stage: str = ""
    """The part of a robust run the iteration belongs to ("gnc round 3 (chordal)"), else ""."""


@dataclasses.dataclass(frozen=True)
class Summary:
    """How an optimisation went. ``error`` is ½ Σ rᵀΩr (gtsam's); ``chi2`` is Σ rᵀΩr (g2o's).
    Frozen: a layer that adds to it builds a new one (``dataclasses.replace``)."""

    method: str
    linear_solver: str
    initial_error: float
    final_error: float
    iterations: list[IterationRecord]
    termination: str
    converged: bool
    phase_times: dict[str, float]
    """Seconds spent in: linearize, assemble, factorize, solve, other."""
    total_time: float
    num_variables: int
    """Size of the linear system (free nodes × dof)."""
    reused: tuple[str, ...] = ()
    """What a warm start reused (for example "sparsity pattern", "symbolic factorization")."""
    initialization: str = "file"
    """How the starting values were made (``posegraph.init.choice.INITIALIZERS``)."""
    initialization_time: float = 0.0
    input_error: float | None = None
    """½ Σ rᵀΩr at the values given, before the initialisation replaced them (None when some
    nodes had no values)."""
    robust: str | None = None
    """The robust kernel and width used ("gnc:3.36", "cauchy:2"), or None for least squares."""
    rejected_edges: list[int] = dataclasses.field(default_factory=list)
    """Indices of the between edges rejected as outliers (robust runs only)."""
    rejected_priors: list[int] = dataclasses.field(default_factory=list)
    """Indices of the priors rejected as outliers (robust runs with ``robust_priors`` only)."""
    edges_under_kernel: int = 0
    """How many between edges the robust kernel covered (the ``robust_edges`` class)."""
    priors_under_kernel: int = 0
    """How many priors it covered (all with ``robust_priors``, else none)."""
    noise: list[dict] = dataclasses.field(default_factory=list)
    """Noise consistency per class of the measurements kept, at the solution
    (``posegraph.robust.noise.NoiseClass.as_dict``), where it was checked: by a robust run
    with the default width, by ``calibrate_noise``, or by the command line."""
    calibration: dict | None = None
    """The factor each class's information was multiplied by, whether the run chose to, and
    the solves that took (``posegraph.robust.calibration.Calibration.as_dict``); None where
    the information was left as given."""

    @property
    def initial_chi2(self) -> float:
        return 2.0 * self.initial_error

    @property
    def final_chi2(self) -> float:
        return 2.0 * self.final_error

    @property
    def num_iterations(self) -> int:
        return len(self.iterations)

    def as_dict(self) -> dict:
        """A JSON-ready dictionary."""
        return {
            "method": self.method,
            "linear_solver": self.linear_solver,
            "initial_error": self.initial_error,
            "final_error": self.final_error,
            "initial_chi2": self.initial_chi2,
            "final_chi2": self.final_chi2,
            "iterations": self.num_iterations,
            "termination": self.termination,
            "converged": self.converged,
            "phase_times": dict(self.phase_times),
            "total_time": self.total_time,
            "num_variables": self.num_variables,
            "reused": list(self.reused),
            "initialization": self.initialization,
            "initialization_time": self.initialization_time,
            "input_error": self.input_error,
            "robust": self.robust,
            "rejected_edges": list(self.rejected_edges),
            "rejected_priors": list(self.rejected_priors),
            "edges_under_kernel": self.edges_under_kernel,
            "priors_under_kernel": self.priors_under_kernel,
            "noise": list(self.noise),
            "calibration": self.calibration,
            "history": [dataclasses.asdict(r) for r in self.iterations],
        }


@dataclasses.dataclass(frozen=True)
class Result:
    """Optimised node values (in the graph's node order) and the summary."""

    values: LieGroup
    summary: Summary
    system: NormalEquations | None = dataclasses.field(default=None, repr=False, compare=False)
    """The ``NormalEquations`` used (pattern and symbolic factorisation), for reuse."""
    linearization: Linearized | None = dataclasses.field(default=None, repr=False, compare=False)
    """The residuals and Jacobians at ``values``, for reuse by a warm start."""
    leverage: Leverage | None = dataclasses.field(default=None, repr=False, compare=False)
    """The deleted residuals and innovations at ``values`` over the kept measurements, where
    GNC's local search computed them there, for reuse by the noise check."""

    def __getstate__(self) -> dict:
        """Pickled and deep-copied without ``system`` and ``leverage`` (their factorisations
        hold CHOLMOD handles that cannot be pickled); a warm start from the copy builds the
        system anew."""
        return {**self.__dict__, "system": None, "leverage": None}


def in_turn(summaries: list[Summary]) -> list[IterationRecord]:
    """The iterations of solves made one after another, numbered and timed from the first."""
    records, offset = [], 0.0
    for summary in summaries:
        for record in summary.iterations:
            records.append(
                dataclasses.replace(
                    record, iteration=len(records) + 1, elapsed=record.elapsed + offset
                )
            )
        offset += summary.total_time
    return records


def in_turn_summary(
    summary: Summary, summaries: list[Summary], work: str, seconds: float
) -> Summary:
    """``summary`` (of one of ``summaries``, solves made one after another, the first before
    the ``seconds`` that the others took part of) with all their iterations (``in_turn``) and
    phase times, and the rest of the ``seconds`` as the phase ``work``."""
    phases = {
        name: sum(each.phase_times.get(name, 0.0) for each in summaries)
        for name in summaries[0].phase_times
    }
    rest = seconds - sum(each.total_time for each in summaries[1:])
    return dataclasses.replace(
        summary, iterations=in_turn(summaries), phase_times={**phases, work: rest}
    )


def named_stages(callback: Callable | None, stage: str) -> Callable | None:
    """``callback``, shown each record of a named stage as "STAGE · stage" (a robust run's
    solves within a calibration, say); None without one."""
    if callback is None:
        return None
    return lambda record: callback(
        dataclasses.replace(record, stage=f"{stage} · {record.stage}") if record.stage else record
    )
