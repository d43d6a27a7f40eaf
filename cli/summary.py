"""Human-readable reports: the optimisation summary, the doctor's diagnosis, the evaluation."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from posegraph.analysis.doctor import Diagnosis
from posegraph.graph import PoseGraph
from posegraph.robust.noise import NoiseClass
from posegraph.solvers import MAX_ITERATIONS, Summary
from posegraph.trajectory.evaluation import Evaluation

if TYPE_CHECKING:
    from posegraph.sim3.scale_drift import ScaleDriftCorrection


def reading_lines(reading: dict) -> list[str]:
    """The report's lines on how the information was read (``common.reading_record``)."""
    lines = []
    if reading["repaired_information"]:
        lines.append(
            f"  information     {reading['repaired_information']} matrices repaired"
            " (--repair-information)"
        )
    if reading["rotation_information"] == "phi":
        lines.append(
            "  rotation info   over φ, as gtsam reads it (g2o weighs it over the quaternion,"
            " 4× less: --g2o-rotation-information)"
        )
    elif reading["rotation_information"] == "quaternion":
        lines.append("  rotation info   over the quaternion's vector, as g2o weighs it")
    return lines


def format_summary(
    source: str,
    graph: PoseGraph,
    summary: Summary,
    written: dict[str, str | None],
    lifted_scale_information: float | None = None,
    reading: dict | None = None,
) -> str:
    """The report of an optimisation; ``written``: the files written, by what they hold;
    ``lifted_scale_information``: that of the SE3 lines of a file mixing SE3 and Sim3;
    ``reading``: how the information was read (``reading_lines``)."""
    phases = summary.phase_times
    lines = [
        f"{source}: {graph.group.__name__}, {graph.num_nodes} nodes, {graph.num_edges} edges",
        *(reading_lines(reading) if reading else []),
        *_lifted_lines(lifted_scale_information),
        _initialisation_line(summary),
        *_error_lines(summary),
        f"  iterations      {summary.num_iterations} ({summary.method}, {summary.linear_solver})",
        _termination_line(summary),
        f"  time            {summary.total_time:.3f} s: "
        + ", ".join(f"{name} {seconds:.3f}" for name, seconds in phases.items()),
        *_robust_lines(graph, summary, lifted_scale_information),
        *_noise_lines(summary),
        *_written_lines(written),
    ]
    return "\n".join(lines)


def _noise_lines(summary: Summary) -> list[str]:
    """The noise check of the measurements kept (χ² per redundant degree of freedom, per
    class), what it finds, and what calibration did; nothing where no check was made."""
    if not summary.noise:
        return []
    classes = [NoiseClass(**c) for c in summary.noise]
    ratios = ", ".join(
        f"{c.kind} {c.chi2_per_dof:.3g}" for c in classes if c.chi2_per_dof is not None
    )
    lines = [f"  noise           χ² per redundant dof {ratios} (1 when the information is right)"]
    for finding in filter(None, (c.finding(robust=bool(summary.robust)) for c in classes)):
        lines.append(f"  {'':<15} {finding[0]}; {finding[1]}")
    calibration = summary.calibration
    if calibration is not None:
        scales = ", ".join(f"{kind} ×{scale:.3g}" for kind, scale in calibration["scales"].items())
        why = "--calibrate-noise"
        if calibration.get("second_opinion"):
            why = (
                "GNC's solution fit the median loop closure worse than its start; GNC at a"
                " tenth of the width fit it better"
            )
        elif calibration.get("consistent_rejections"):
            why = (
                f"GNC rejected {calibration['consistent_rejections']} measurements that the"
                " noise of those it kept explains"
            )
        elif calibration["automatic"]:
            why = "GNC kept gross outliers under the noise the residuals show"
        lines.append(
            f"  calibrated      information {scales} ({why}; {_solves(calibration['solves'])})"
        )
    return lines


def format_scale_drift(
    source: str,
    correction: ScaleDriftCorrection,
    ate: tuple[float, float] | None,
    written: dict[str, str | None],
    lifted_scale_information: float | None = None,
) -> str:
    """The report of a scale-drift correction; ``ate``: the ATE (SE3-aligned) before and after,
    against ground truth, if given; ``written``: the files written, by what they hold;
    ``lifted_scale_information``: that of the SE3 lines lifted to Sim3, by the reader (a file
    mixing SE3 and Sim3) or by the correction (SE3 lines only)."""
    summary, graph, scales = correction.result.summary, correction.graph, correction.scales
    lines = [
        f"{source}: {graph.num_nodes} poses, {graph.num_edges} edges, optimised in Sim3",
        *_lifted_lines(lifted_scale_information),
        _initialisation_line(summary),
        *_error_lines(summary),
        f"  scales          {scales.min():.4g} … {scales.max():.4g}",
        _termination_line(summary),
        f"  time            {summary.total_time:.3f} s, {summary.num_iterations} iterations",
        *_robust_lines(graph, summary, lifted_scale_information),
    ]
    if ate is not None:
        lines.append(f"  ATE (SE3-aligned, no scale)  before {ate[0]:.6g}  after {ate[1]:.6g}")
    return "\n".join([*lines, *_written_lines(written)])


def _initialisation_line(summary: Summary) -> str:
    return f"  initialisation  {summary.initialization} ({summary.initialization_time:.3f} s)"


def _termination_line(summary: Summary) -> str:
    """How the run ended; a run stopped by the iteration limit says how to raise it."""
    remark = "" if summary.converged else " (not converged)"
    if summary.termination == MAX_ITERATIONS:
        remark = " (not converged; --max-iterations raises the limit)"
    return f"  termination     {summary.termination}{remark}"


def _robust_lines(
    graph: PoseGraph, summary: Summary, lifted_scale_information: float | None
) -> list[str]:
    """What a robust run's kernel covered and rejected, with a hint when it rejected most of
    it (and on lifted SE3 odometry, one on its scale information); nothing for least
    squares."""
    if not summary.robust:
        return []
    lines = [
        f"  robust          {summary.robust} on {_covered(graph, summary)}: "
        + _rejected(graph, summary)
    ]
    if 2 * len(summary.rejected_edges) > summary.edges_under_kernel:
        hint = MOST_REJECTED.format(kernel=summary.robust.partition(":")[0])
        lines.append(f"  {'':<15} {hint}")
        if lifted_scale_information is not None:
            lines.append(f"  {'':<15} {STIFF_SCALE.format(_scale_sigma(lifted_scale_information))}")
    return lines


def _lifted_lines(scale_information: float | None) -> list[str]:
    """How SE3 lines were lifted to Sim3; nothing if none were."""
    if scale_information is None:
        return []
    return [
        f"  lifted          SE3 lines to Sim3: log-scale information {scale_information:.4g}, a"
        f" scale change of {_scale_sigma(scale_information)} per edge (1σ; --scale-information)"
    ]


def _scale_sigma(scale_information: float) -> str:
    """The 1σ relative scale change that log-scale information allows, as a percentage."""
    return f"{100.0 / math.sqrt(scale_information):.2g}%"


def _written_lines(written: dict[str, str | None]) -> list[str]:
    return [f"  {what:<15} {path}" for what, path in written.items() if path]


MOST_REJECTED = (
    "most of the edges under the kernel were rejected: if they are true, their information (or"
    " the trusted edges') overstates their accuracy: --calibrate-noise estimates it, taking"
    " most of them as true; or widen the kernel (--robust {kernel}:WIDTH)"
)
"""The report's hint when a robust run rejected more than half of the edges it covered."""

STIFF_SCALE = (
    "the lifted SE3 odometry allows a scale change of only {} per edge (1σ): loops that"
    " correct a faster drift look false to it; set --scale-information to 1/σ², σ the expected"
    " scale drift per edge (1e4 for 1%)"
)
"""The second hint, on a file whose SE3 lines were lifted to Sim3."""

SHOWN_REJECTED = 5
"""Rejected edges and priors named in the report; ``--json`` lists them all."""


def _covered(graph: PoseGraph, summary: Summary) -> str:
    """What the robust kernel covered: "245 of 644 edges", and " and 30 priors" if any."""
    covered = f"{summary.edges_under_kernel} of {graph.num_edges} edges"
    if summary.priors_under_kernel:
        covered += f" and {summary.priors_under_kernel} priors"
    return covered


def _rejected(graph: PoseGraph, summary: Summary) -> str:
    """What a robust run rejected: the edges by their nodes' ids (i→j), the priors by their
    node's id, the first ``SHOWN_REJECTED`` of each."""
    ids = graph.node_ids
    edges = [f"{ids[graph.edges.i[k]]}→{ids[graph.edges.j[k]]}" for k in summary.rejected_edges]
    priors = [f"on {ids[graph.priors.i[k]]}" for k in summary.rejected_priors]
    parts = [f"{len(edges)} edge(s) rejected{_listed(edges)}"]
    if priors:
        parts.append(f"{len(priors)} prior(s) rejected{_listed(priors)}")
    more = max(len(edges), len(priors)) > SHOWN_REJECTED
    return "; ".join(parts) + (" (--json lists all)" if more else "")


def _listed(names: list[str]) -> str:
    """ ": a, b, c" of at most ``SHOWN_REJECTED`` names, "…" for the rest; "" if none."""
    if not names:
        return ""
    return ": " + ", ".join(names[:SHOWN_REJECTED]) + (", …" if len(names) > SHOWN_REJECTED else "")


def _error_lines(summary: Summary) -> list[str]:
    """Error and χ² from the input values, through the initialisation, to the optimum; of a
    robust run, its robust cost (ρ the kernel, s = rᵀΩr)."""
    steps = [(summary.initial_error, None)]
    if summary.input_error is not None and summary.input_error != summary.initial_error:
        steps = [(summary.input_error, "input"), (summary.initial_error, summary.initialization)]
    names = (
        ("error ½Σρ(s)", "chi2  Σρ(s)") if summary.robust else ("error ½Σrᵀ Ω r", "chi2  Σrᵀ Ω r")
    )
    lines = []
    for name, factor in zip(names, (1.0, 2.0), strict=True):
        path = " -> ".join(
            f"{factor * value:.10g}" + (f" ({label})" if label else "") for value, label in steps
        )
        lines.append(f"  {name:<15} {path} -> {factor * summary.final_error:.10g}")
    return lines


def format_diagnosis(d: Diagnosis, reading: dict | None = None) -> str:
    counts = ", ".join(f"{tag} {count}" for tag, count in d.tag_counts.items())
    lines = [
        f"{d.path} ({d.file_format}): {d.group} pose graph",
        f"  lines           {counts}",
        f"  graph           {d.nodes} nodes, {d.edges} edges ({d.loop_closures} loop closures"
        f" between nodes that are not consecutive), {d.priors} priors",
        f"  components      {len(d.components)} (sizes {', '.join(map(str, d.components[:5]))})",
        f"  gauge           {d.gauge}",
        *(reading_lines(reading) if reading else []),
    ]
    kinds = []
    if d.singular_information:
        kinds.append(f"{d.singular_information} singular (directions not measured)")
    if d.condition_numbers:
        c = d.condition_numbers
        kinds.append(
            f"{'the others ' if kinds else ''}SPD, condition number min {c['min']:.3g}, "
            f"median {c['median']:.3g}, max {c['max']:.3g}"
        )
    if kinds:
        lines.append(f"  information     {'; '.join(kinds)}")
    lines.extend(_lifted_lines(d.lifted_scale_information))
    lines.append(f"  initial error   {d.initial_error:.10g} (½Σrᵀ Ω r), chi2 {d.initial_chi2:.10g}")
    if d.noise:
        classes = ", ".join(
            f"{c.kind} {c.chi2_per_dof:.3g} ({c.above_quantile} fail χ²(0.999))"
            if c.chi2_per_dof is not None
            else f"{c.kind} not redundant"
            for c in d.noise
        )
        lines.append(f"  noise           χ² per dof at the least-squares optimum: {classes}")
    if d.problems:
        lines.append(f"  problems        {len(d.problems)}")
        for problem in d.problems:
            lines.append(f"    - {problem.what}")
            lines.append(f"      → {problem.suggestion}")
    else:
        lines.append("  problems        none found")
    return "\n".join(lines)


def format_evaluation(e: Evaluation) -> str:
    def row(name: str, stats, unit: str) -> str:
        return (
            f"  {name:<16} rmse {stats.rmse:.6g}{unit}  mean {stats.mean:.6g}  "
            f"median {stats.median:.6g}  max {stats.max:.6g}"
        )

    lines = [
        f"matched {e.matched} of {e.estimate_poses} poses (keys within {e.max_difference:g}); "
        f"alignment {e.alignment} (scale {float(e.alignment_transform.scale):.6g})",
        row("ATE", e.ate, ""),
        row("RPE translation", e.rpe_translation, ""),
        row("RPE rotation", e.rpe_rotation_deg, "°"),
    ]
    if e.drift is None:
        lines.append(
            f"  {'drift':<16} no segment fits: the ground truth's path is shorter than"
            f" {min(e.segment_lengths):g} (--segment-lengths)"
        )
    else:
        lines.append(
            f"  {'drift':<16} translation {e.drift.translation_percent:.4g}%  rotation"
            f" {e.drift.rotation_deg_per_100m:.4g}°/100 m over {e.drift.segments} segments of"
            f" {_lengths(e.drift.lengths)} (KITTI's metric)"
        )
    if e.planar_ate_floor is not None:
        lines.append(
            f"  {'ATE floor':<16} rmse {e.planar_ate_floor:.6g}  (the estimate is planar: the"
            " ground truth's RMS distance from its plane, below which no planar ATE can go)"
        )
    return "\n".join(lines)


def _lengths(lengths: tuple[float, ...]) -> str:
    """ "100–800" of the segment lengths, or the one length."""
    low, high = min(lengths), max(lengths)
    return f"{low:g}" if low == high else f"{low:g}–{high:g}"


def _solves(count: int) -> str:
    return f"{count} more solve{'' if count == 1 else 's'}"
