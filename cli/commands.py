"""The handlers of ``optimize``, ``info``, ``convert``, ``plot``, ``eval`` and ``bench`` (``scale_drift``
has its own module); each reads its inputs, calls one library function, and prints."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys

import numpy as np

import posegraph
from posegraph.analysis.doctor import diagnose
from posegraph.io import ReadResult
from posegraph.io.atomic import output_batch
from posegraph.io.conversion import convert as convert_graph
from posegraph.io.conversion import output_format
from posegraph.io.covariances import write_covariances
from posegraph.problem.cholesky import NotPositiveDefinite
from posegraph.robust.calibration import kept_noise
from posegraph.solvers import Summary
from posegraph.trajectory.evaluation import evaluate

from .common import (
    Inputs,
    Kept,
    about,
    check_drop_rejected,
    check_output,
    check_paths,
    check_writable,
    emit,
    noting_interruption,
    output_graph,
    reading_record,
    set_aside_rejected,
    solving_options,
    talks,
)
from .errors import EXIT_NOT_CONVERGED, EXIT_OK, UsageError
from .progress import Progress
from .summary import format_diagnosis, format_evaluation, format_summary


def optimize(args: argparse.Namespace) -> int:
    outputs = {"-o": args.output, "--plot": args.plot, "--covariances": args.covariances}
    check_paths([args.input], outputs, args.overwrite)
    check_output(args.output)
    check_output(args.plot, figure=True)
    check_output(args.covariances, text=True)
    check_drop_rejected(args)
    solving = solving_options(args)
    inputs = Inputs(args)
    read = inputs.graph(args.input)
    graph, kept = set_aside_rejected(read, args.readmit_rejected)
    if args.fix:
        try:
            graph.fix(args.fix)
        except KeyError as error:
            raise UsageError(f"--fix: {error.args[0]}") from None
    check_writable(args.input, graph, args.output)
    before = graph.copy()
    smoother = posegraph.Smoother(graph)
    with Progress(talks(args), args.solver) as progress:
        with about(args.input):  # values the initialisation cannot hold, say
            result = smoother.optimize(
                callback=progress, calibrate_noise=args.calibrate_noise or None, **solving
            )
    summary = noting_interruption(progress, result.summary)
    _refuse_non_finite(summary, args.input)
    summary = _with_noise(graph, result, summary)
    wrote = _write_optimised(args, read, smoother, before, kept)
    record = {
        "command": "optimize",
        "input": args.input,
        "output": args.output,
        "plot": args.plot,
        "covariances": args.covariances,
        "group": graph.group.__name__,
        "nodes": graph.num_nodes,
        "edges": graph.num_edges,
        "lifted_scale_information": read.lifted_scale_information,
        **reading_record(read, args),
        "summary": summary.as_dict(),
        "skipped_lines": inputs.skipped_lines,
    }
    written = {"wrote": wrote, "plotted": args.plot, "covariances": args.covariances}
    text = format_summary(
        args.input, graph, summary, written, read.lifted_scale_information, record
    )
    emit(args, record, text, inputs.warnings)
    return EXIT_OK if summary.converged else EXIT_NOT_CONVERGED


def _with_noise(graph: posegraph.PoseGraph, result: posegraph.Result, summary: Summary) -> Summary:
    """The summary with the noise check of the measurements kept, where the run made none
    (nor where it was stopped, or the solution has no covariance)."""
    if summary.noise or not summary.converged:
        return summary
    try:
        noise = kept_noise(graph, result)
    except (np.linalg.LinAlgError, NotPositiveDefinite, ValueError):
        return summary
    return dataclasses.replace(summary, noise=[c.as_dict() for c in noise])


def _refuse_non_finite(summary: Summary, source: str) -> None:
    """A result whose error overflows is refused before anything is written."""
    if not math.isfinite(summary.final_error):
        raise UsageError(
            f"the optimisation ended with error {summary.final_error} (at the file's values: "
            f"{summary.input_error}); numbers this large overflow in double precision. Nothing "
            "written",
            source,
        )


def _write_optimised(
    args: argparse.Namespace,
    read: ReadResult,
    smoother: posegraph.Smoother,
    before: posegraph.PoseGraph,
    kept: Kept | None,
) -> str | None:
    """``optimize``'s outputs, all written or none (``output_batch``): the graph (``-o``, what
    was rejected or set aside marked: ``output_graph``), the figure and the covariances. The
    graph is staged first, so that Ctrl-C during the later ones still writes the converged
    result. Returns how the report names ``-o``."""
    graph = smoother.graph
    output, rejected, wrote = output_graph(args, smoother, read.graph, kept)
    with output_batch():
        if args.output:
            convert_graph(
                output,
                args.output,
                output_format(args.output),
                sim3_dialect=read.sim3_dialect or "a",
                g2o_rotation_information=args.g2o_rotation_information,
                rejected=rejected,
            )
        if args.plot:
            from posegraph.plotting import plot_graphs

            plot_graphs(
                [("initial", before), ("optimised", smoother)],
                args.plot,
                title=os.path.basename(args.input),
            )
        if args.covariances:
            covariances = _covariances(args.input, smoother)
            write_covariances(args.covariances, graph.group.__name__, graph.node_ids, covariances)
    return wrote


def _covariances(source: str, smoother: posegraph.Smoother) -> np.ndarray:
    """Every node's marginal covariance at the graph's values, before anything is written."""
    try:
        return posegraph.marginals(smoother, smoother.graph.node_ids, require_measured=True)
    except NotPositiveDefinite as error:
        raise UsageError(
            f"{error}. Nothing written (without --covariances, the optimised graph is)", source
        ) from None


def info(args: argparse.Namespace) -> int:
    # Lenient always: the report lists what it skipped, by kind, as problems.
    inputs = Inputs(args, warn_skipped=False, lenient=True)
    read = inputs.graph(args.input)
    diagnosis = diagnose(read)
    reading = reading_record(read, args)
    record = {
        "command": "info",
        **diagnosis.as_dict(),
        **reading,
        "skipped_lines": inputs.skipped_lines,
    }
    emit(args, record, format_diagnosis(diagnosis, reading))
    return EXIT_OK


def convert(args: argparse.Namespace) -> int:
    check_paths([args.input], {"-o": args.output}, args.overwrite)
    check_output(args.output, args.to, remedy="; say --to g2o|toro|tum|kitti")
    inputs = Inputs(args)
    read = inputs.graph(args.input)
    graph = read.graph
    check_writable(args.input, graph, args.output, to=args.to)
    written = convert_graph(
        graph,
        args.output,
        args.to,
        args.sim3_dialect,
        args.g2o_rotation_information,
        read.rejected,  # kept marked
    )
    record = {
        "command": "convert",
        "input": args.input,
        "output": args.output,
        "format": written,
        "nodes": graph.num_nodes,
        "edges": graph.num_edges,
        "skipped_lines": inputs.skipped_lines,
    }
    text = f"wrote {args.output} ({written}, {graph.num_nodes} poses)"
    emit(args, record, text, inputs.warnings)
    return EXIT_OK


def plot(args: argparse.Namespace) -> int:
    from posegraph.plotting import plot_graphs

    check_paths(args.inputs, {"-o": args.output}, None)
    check_output(args.output, figure=True)
    inputs = Inputs(args)
    graphs = [(os.path.basename(p), inputs.graph(p)) for p in args.inputs]  # rejections too
    plot_graphs(graphs, args.output, title=args.title, view=args.view)
    record = {
        "command": "plot",
        "inputs": args.inputs,
        "output": args.output,
        "skipped_lines": inputs.skipped_lines,
    }
    emit(args, record, f"wrote {args.output}", inputs.warnings)
    return EXIT_OK


def eval(args: argparse.Namespace) -> int:  # noqa: A001 - the subcommand's name
    check_paths([args.estimate, args.ground_truth], {"--plot": args.plot}, None)
    check_output(args.plot, figure=True)
    inputs = Inputs(args)
    estimate = inputs.trajectory(args.estimate)
    truth = inputs.trajectory(args.ground_truth)
    with about(args.estimate, args.ground_truth):  # they do not pair, say
        evaluation = evaluate(
            estimate,
            truth,
            args.align,
            args.delta,
            args.max_time_difference,
            tuple(args.segment_lengths),
        )
    if args.plot:
        from posegraph.plotting import plot_trajectories

        plot_trajectories(
            [
                ("ground truth", truth.positions),
                (f"estimate ({args.align}-aligned)", evaluation.aligned_estimate.translation),
            ],
            args.plot,
            title=f"ATE RMSE {evaluation.ate.rmse:.4g}",
        )
    record = {
        "command": "eval",
        "estimate": args.estimate,
        "ground_truth": args.ground_truth,
        "plot": args.plot,
        **evaluation.as_dict(),
        "skipped_lines": inputs.skipped_lines,
    }
    emit(args, record, format_evaluation(evaluation), inputs.warnings)
    return EXIT_OK


def bench(args: argparse.Namespace) -> int:
    from posegraph.benchmarks.optimizer import benchmark_files, run

    files = benchmark_files()
    if args.graphs:
        files = [f for f in files if f.stem in args.graphs]
    if not files:
        raise UsageError("no benchmark graphs found (../shared/datasets or gtsam's Data/)")
    table = run(files, args.repeats, args.rounds, args.budget, talks(args), args.solver)
    if args.json:
        print(json.dumps({"command": "bench", "solver": args.solver, "table": table}, indent=2))
    elif not args.quiet:
        sys.stdout.flush()
    return EXIT_OK
