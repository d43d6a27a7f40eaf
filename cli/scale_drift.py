"""``posegraph scale-drift``: correct a monocular trajectory's scale drift in Sim3, report the
ATE before and after against ground truth, and write the poses or the Sim3 graph."""

from __future__ import annotations

import argparse
import dataclasses
import os

import posegraph
from posegraph.io import ReadResult
from posegraph.io.atomic import output_batch
from posegraph.io.conversion import convert as convert_graph
from posegraph.io.conversion import output_format
from posegraph.io.trajectories import Trajectory, write_trajectory
from posegraph.sim3.scale_drift import correct_scale_drift, lift_graph
from posegraph.trajectory.evaluation import evaluate

from .common import (
    Inputs,
    Kept,
    about,
    check_drop_rejected,
    check_output,
    check_paths,
    check_writable,
    cost_label,
    emit,
    noting_interruption,
    output_graph,
    reading_record,
    set_aside_rejected,
    solving_options,
    talks,
)
from .errors import EXIT_NOT_CONVERGED, EXIT_OK
from .progress import Progress
from .summary import format_scale_drift

NO_SIM3_EDGE = (
    "no Sim3 edge: each loop closure only says that its ends share one scale, which corrects"
    " scale drift only where its translation is metric; Sim3 loop closures (EDGE_SIM3:EXPMAP)"
    " carry the scale change"
)


def scale_drift(args: argparse.Namespace) -> int:
    check_paths([args.input, args.gt], {"-o": args.output, "--plot": args.plot}, args.overwrite)
    check_output(args.output, args.to)
    check_output(args.plot, figure=True)
    check_drop_rejected(args)
    solving = solving_options(args)
    inputs = Inputs(args)
    read = inputs.graph(args.input)
    graph, kept = set_aside_rejected(read, args.readmit_rejected)
    if graph.group is posegraph.SE3:
        inputs.warn(f"{args.input}: {NO_SIM3_EDGE}")
    if graph.group is not posegraph.SE2:  # refused below, by the correction
        check_writable(args.input, graph, args.output, args.to, posegraph.Sim3)
    truth = inputs.trajectory(args.gt) if args.gt else None  # read before the work
    before = Trajectory.of_graph(graph)
    progress = Progress(talks(args), args.solver, args.max_iterations, cost_label(args))
    with progress, progress.interruptible():
        progress.begin("initialising")
        with about(args.input):  # a graph it cannot correct (SE2), values beyond doubles
            correction = correct_scale_drift(
                graph, args.scale_information, args.convention, callback=progress, **solving
            )
    summary = noting_interruption(progress, correction.result.summary)
    result = dataclasses.replace(correction.result, summary=summary)
    correction = dataclasses.replace(correction, result=result)
    # Lifted by the reader (a file mixing SE3 and Sim3) or by the correction (SE3 only).
    lifted = read.lifted_scale_information
    if lifted is None:
        lifted = correction.lifted_scale_information
    after = Trajectory.of_graph(correction.graph, correction.poses)  # as asked for
    corrected = Trajectory.of_graph(correction.graph)  # world-from-camera
    ate = None
    if truth is not None:
        ate = tuple(evaluate(poses, truth, "se3").ate.rmse for poses in (before, corrected))
    with output_batch():  # all written or none; Ctrl-C during the figure keeps -o
        wrote = _write_corrected(args, read, correction, after, kept)
        if args.plot:
            _plot_correction(args, before, corrected, truth)
    record = {
        "command": "scale-drift",
        "input": args.input,
        "output": args.output,
        "plot": args.plot,
        "convention": args.convention,
        "nodes": graph.num_nodes,
        "edges": graph.num_edges,
        "scale_range": [float(correction.scales.min()), float(correction.scales.max())],
        "lifted_scale_information": lifted,
        **reading_record(read, args),
        "summary": summary.as_dict(),
        "ate_before": ate[0] if ate else None,
        "ate_after": ate[1] if ate else None,
        "skipped_lines": inputs.skipped_lines,
    }
    written = {"wrote": wrote, "plotted": args.plot}
    text = format_scale_drift(args.input, correction, ate, written, lifted)
    emit(args, record, text, inputs.warnings)
    return EXIT_OK if summary.converged else EXIT_NOT_CONVERGED


def _write_corrected(
    args, read: ReadResult, correction, after: Trajectory, kept: Kept | None
) -> str | None:
    """``scale-drift``'s ``-o``: the corrected poses (TUM or KITTI) or the Sim3 graph (what
    was rejected or set aside marked: ``output_graph``). Returns how the report names it."""
    source = read.graph
    if kept is not None and source.group is not correction.graph.group:  # an SE3 file's
        source = lift_graph(source, correction.lifted_scale_information)
    output, rejected, wrote = output_graph(args, correction.smoother, source, kept)
    if args.output:
        written = output_format(args.output, args.to)
        if written in ("tum", "kitti"):
            write_trajectory(after, args.output, written)
        else:
            dialect = read.sim3_dialect or "a"
            convert_graph(output, args.output, written, dialect, rejected=rejected)
    return wrote


def _plot_correction(args, before: Trajectory, corrected: Trajectory, truth) -> None:
    """``scale-drift --plot``: the trajectories before and after (and the ground truth)."""
    from posegraph.plotting import plot_trajectories

    curves = [("before", before.positions), ("corrected", corrected.positions)]
    if truth is not None:
        curves.append(("ground truth", truth.positions))
    title = f"scale-drift correction: {os.path.basename(args.input)} (top view)"
    plot_trajectories(curves, args.plot, title=title, view="top")
