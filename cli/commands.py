"""The handlers of ``optimize``, ``info``, ``convert``, ``plot``, ``eval`` and ``bench`` (``scale_drift``
has its own module); each reads its inputs, calls one library function, and prints."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys

import numpy as np

import posegraph
from posegraph.analysis.doctor import diagnose
from posegraph.certification import require_certifiable
from posegraph.graph.information import information_from_sigmas
from posegraph.io import ReadResult
from posegraph.io.atomic import output_batch
from posegraph.io.conversion import (
    GRAPH_FORMATS,
    input_format,
    is_trajectory_file,
    output_format,
)
from posegraph.io.conversion import convert as convert_graph
from posegraph.io.covariances import write_covariances
from posegraph.io.trajectories import Trajectory
from posegraph.problem.cholesky import NotPositiveDefinite
from posegraph.robust.calibration import kept_noise
from posegraph.solvers import Summary
from posegraph.trajectory.evaluation import evaluate, paired_by_index
from posegraph.trajectory.odometry import odometry_graph

from .certify import certified_if_asked, info_certificate, with_certificate
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
    reports,
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
    check_output(args.output, args.to)
    check_output(args.plot, figure=True, interactive=True)
    check_output(args.covariances, text=True)
    check_drop_rejected(args)
    solving = solving_options(args)
    inputs = Inputs(args)
    progress = Progress(talks(args), args.solver, args.max_iterations, cost_label(args))
    with progress:
        with progress.stage(f"reading {os.path.basename(args.input)}"):
            read = inputs.graph(args.input)
        graph, kept = set_aside_rejected(read, args.readmit_rejected)
        if args.fix:
            try:
                graph.fix(args.fix)
            except KeyError as error:
                raise UsageError(f"--fix: {error.args[0]}") from None
        check_writable(args.input, graph, args.output, to=args.to)
        if args.certify:
            require_certifiable(graph)  # before any work
        before = graph.copy()
        smoother = posegraph.Smoother(graph)
        progress.begin("initialising")
        with progress.interruptible(), about(args.input):  # values beyond doubles, say
            result = smoother.optimize(
                callback=progress, calibrate_noise=args.calibrate_noise or None, **solving
            )
        progress.end()
        summary = noting_interruption(progress, result.summary)
        _refuse_non_finite(summary, args.input)
        if not summary.noise and summary.converged and reports(args):
            with progress.stage("noise check"):
                summary = _with_noise(graph, result, summary)
        certificate = certified_if_asked(args, smoother, progress)
        writing = args.output or args.plot or args.covariances
        with progress.stage("writing") if writing else contextlib.nullcontext():
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
    text = with_certificate(record, text, certificate)
    emit(args, record, text, inputs.warnings)
    return EXIT_OK if summary.converged else EXIT_NOT_CONVERGED


def _with_noise(graph: posegraph.PoseGraph, result: posegraph.Result, summary: Summary) -> Summary:
    """The summary with the noise check of the measurements kept (unless the solution has no
    covariance); for a converged run that made none."""
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
    was rejected or set aside marked: ``output_graph``), the figure (with the covariances'
    ellipses, when asked for) and the covariances. The graph is staged first, so that Ctrl-C
    during the later ones still writes the converged result. Returns how the report names
    ``-o``."""
    graph = smoother.graph
    output, rejected, wrote = output_graph(args, smoother, read.graph, kept)
    with output_batch():
        if args.output:
            convert_graph(
                output,
                args.output,
                output_format(args.output, args.to),
                sim3_dialect=read.sim3_dialect or "a",
                g2o_rotation_information=args.g2o_rotation_information,
                rejected=rejected,
            )
        covariances = _covariances(args.input, smoother) if args.covariances else None
        if args.plot:
            from posegraph.plotting import plot_graphs

            plot_graphs(
                [("initial", before), ("optimised", smoother)],
                args.plot,
                title=os.path.basename(args.input),
                covariances=covariances,
            )
        if args.covariances:
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
    kept, _ = set_aside_rejected(read, False)  # a robust run's rejections stay out
    text = info_certificate(args, kept, record, format_diagnosis(diagnosis, reading))
    emit(args, record, text)
    return EXIT_OK


def convert(args: argparse.Namespace) -> int:
    check_paths([args.input], {"-o": args.output}, args.overwrite)
    check_output(args.output, args.to, remedy="; say --to g2o|toro|tum|kitti")
    inputs = Inputs(args)
    rejected = None
    if is_trajectory_file(args.input):
        information = information_from_sigmas(posegraph.SE3, *args.sigmas)
        with about(args.input):
            graph = odometry_graph(inputs.trajectory(args.input), information)
    else:
        read = inputs.graph(args.input)
        graph, rejected = read.graph, read.rejected  # kept marked
    check_writable(args.input, graph, args.output, to=args.to)
    written = convert_graph(
        graph, args.output, args.to, args.sim3_dialect, args.g2o_rotation_information, rejected
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
    what = f"{graph.num_nodes} poses"
    if written in GRAPH_FORMATS:
        what += f", {graph.num_edges} edges"
    emit(args, record, f"wrote {args.output} ({written}, {what})", inputs.warnings)
    return EXIT_OK


def plot(args: argparse.Namespace) -> int:
    from posegraph.plotting import plot_graphs

    check_paths(args.inputs, {"-o": args.output}, None)
    check_output(args.output, figure=True, interactive=True)
    inputs = Inputs(args)
    graphs = [  # a graph file's rejections too
        (os.path.basename(p), inputs.trajectory(p) if is_trajectory_file(p) else inputs.graph(p))
        for p in args.inputs
    ]
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
    if args.match_by_index:
        estimate, truth = paired_by_index(estimate, truth)
    else:
        _refuse_unequal_kitti(args, estimate, truth)
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
        from posegraph.plotting import plot_evaluation

        title = f"{os.path.basename(args.estimate)}: ATE RMSE {evaluation.ate.rmse:.4g}"
        plot_evaluation(
            evaluation, truth.positions, args.plot, args.plot_mode, args.plot_colormap_max, title
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


def _refuse_unequal_kitti(
    args: argparse.Namespace, estimate: Trajectory, truth: Trajectory
) -> None:
    """KITTI files pair line by line: of different lengths, one was cut or has gaps, which the
    user must say to accept (as evo refuses them)."""
    kitti = all(input_format(path) == "kitti" for path in (args.estimate, args.ground_truth))
    if kitti and len(estimate.keys) != len(truth.keys):
        raise UsageError(
            f"{args.estimate} has {len(estimate.keys)} poses and {args.ground_truth}"
            f" {len(truth.keys)}: KITTI files pair line by line; pass --match-by-index to pair"
            " the first ones of each"
        )


def bench(args: argparse.Namespace) -> int:
    from posegraph.benchmarks.optimizer import benchmark_files, gtsam_available, run

    files = benchmark_files()
    if args.graphs:
        files = [f for f in files if f.stem in args.graphs]
    if not files:
        raise UsageError(
            "no benchmark graphs found: run 'posegraph datasets download all' (or set"
            " POSEGRAPH_SHARED_DATASETS to a folder that holds them)"
        )
    with_gtsam = gtsam_available()
    if not with_gtsam and talks(args):
        print(
            "gtsam is not installed, so its columns are empty; add it with"
            " pip install 'posegraph[bench]'",
            file=sys.stderr,
        )
    table = run(files, args.repeats, args.rounds, args.budget, talks(args), args.solver, with_gtsam)
    if args.json:
        document = {"command": "bench", "solver": args.solver, "gtsam": with_gtsam, "table": table}
        print(json.dumps(document, indent=2))
    elif not args.quiet:
        sys.stdout.flush()
    return EXIT_OK
