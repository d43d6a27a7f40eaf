"""One handler per subcommand; each reads its inputs, calls one library function, and prints."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
from collections.abc import Iterator

import numpy as np

import posegraph
from posegraph.conversion import GRAPH_FORMATS, load_trajectory, output_format, unwritable_to
from posegraph.conversion import convert as convert_graph
from posegraph.doctor import diagnose
from posegraph.evaluation import evaluate
from posegraph.io import ReadOptions, ReadResult, read_graph
from posegraph.io.atomic import check_replaceable
from posegraph.io.covariances import write_covariances
from posegraph.lie import LieGroup
from posegraph.solvers import SolverOptions, Summary
from posegraph.sparse_cholesky import NotPositiveDefinite
from posegraph.trajectory_io import Trajectory

from .errors import EXIT_NOT_CONVERGED, EXIT_OK, UsageError, warn
from .progress import Progress
from .summary import format_diagnosis, format_evaluation, format_scale_drift, format_summary


def _options(args: argparse.Namespace) -> ReadOptions:
    return ReadOptions(
        lenient=args.lenient,
        g2o_rotation_information=args.g2o_rotation_information,
        identity_information=args.identity_information,
        edge2_order=args.edge2_order,
        scale_information=args.scale_information,
    )


class _Inputs:
    """A command's input files, read with its options. What lenient reading skipped is kept for
    the JSON document (``skipped_lines``) and, with ``warn_skipped`` in text mode, reported on
    stderr as soon as it is read: the results leave out what those lines say (a node whose
    vertex line was skipped keeps its edges)."""

    def __init__(self, args: argparse.Namespace, warn_skipped: bool = True) -> None:
        self.options = _options(args)
        self.warn_skipped = warn_skipped and _talks(args)
        self.skipped_lines: list[dict] = []

    def graph(self, path: str) -> ReadResult:
        read = read_graph(path, self.options)
        self.skipped_lines += [
            {"path": path, "reason": why, "count": count, "first_line": line}
            for why, count, line in read.skipped_by_reason()
        ]
        if read.skipped and self.warn_skipped:
            warn(f"{path}: {read.skipped_report()}; the results leave out what those lines say")
        return read

    def trajectory(self, path: str) -> Trajectory:
        return load_trajectory(path, self.graph)


def _json_safe(value):
    """``value`` with every float that is not finite as None (JSON has no NaN or ∞)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(item) for item in value]
    return value


def _talks(args: argparse.Namespace) -> bool:
    """Whether the command reports as text on the terminal: neither ``--json`` nor ``--quiet``
    (progress and warnings are shown then)."""
    return not (args.json or args.quiet)


def _emit(args: argparse.Namespace, record: dict, text: str) -> None:
    if args.json:
        print(json.dumps(_json_safe(record), indent=2, allow_nan=False))
    elif not args.quiet:
        print(text)


def _refuse_to_overwrite(source: str, target: str | None, allowed: bool) -> None:
    if target and not allowed and os.path.exists(target) and os.path.samefile(source, target):
        raise UsageError(
            "refusing to overwrite the input file; pass --overwrite to allow it", source
        )


def _check_output(
    path: str | None,
    to: str | None = None,
    figure: bool = False,
    text: bool = False,
    remedy: str = "",
) -> None:
    """Fail before any work if ``path`` cannot be written: a format not known by its suffix
    (or ``to``; a ``figure``'s by matplotlib; ``text`` has one format; ``remedy`` follows that
    refusal), a folder that does not exist, or a read-only file."""
    if path is None:
        return
    try:
        if figure:
            from posegraph.plotting import check_figure_path

            check_figure_path(path)
        elif not text:
            output_format(path, to)
    except ValueError as error:  # its message starts with the path, which UsageError adds
        raise UsageError(str(error).removeprefix(f"{path}: ") + remedy, path) from None
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise UsageError(f"cannot write: there is no folder {folder}", path)
    if os.path.isdir(path):
        raise UsageError("is a folder, not a file", path)
    check_replaceable(path)


def _check_drop_rejected(args: argparse.Namespace) -> None:
    """``--drop-rejected`` needs a robust run, and a graph file to leave its rejections out of."""
    if not args.drop_rejected:
        return
    if args.robust is None:
        raise UsageError("--drop-rejected needs --robust: only a robust run rejects measurements")
    if args.output is None or output_format(args.output) not in GRAPH_FORMATS:
        raise UsageError(
            "--drop-rejected leaves the rejected edges out of the graph that -o writes: give -o a"
            " g2o or TORO file",
            args.output,
        )


def _output_graph(
    args: argparse.Namespace, graph: posegraph.PoseGraph
) -> tuple[posegraph.PoseGraph, str | None]:
    """The graph that ``-o`` gets (without the rejected measurements, with ``--drop-rejected``)
    and how the report names the file."""
    if not args.drop_rejected:
        return graph, args.output
    inliers = graph.without_rejected()
    left_out = f"{graph.num_edges - inliers.num_edges} rejected edge(s)"
    if len(inliers.priors) < len(graph.priors):
        left_out += f" and {len(graph.priors) - len(inliers.priors)} rejected prior(s)"
    return inliers, f"{args.output} (without the {left_out})"


def _check_writable(
    source: str,
    graph: posegraph.PoseGraph,
    path: str | None,
    to: str | None = None,
    group: type[LieGroup] | None = None,
) -> None:
    """Fail before any work if the graph read from ``source`` (lifted to ``group``, if given)
    cannot be written to ``path`` as ``to`` (``posegraph.conversion.unwritable_to``)."""
    reason = None if path is None else unwritable_to(graph, path, to, group)
    if reason is not None:
        raise UsageError(reason, source)


@contextlib.contextmanager
def _about(*paths: str) -> Iterator[None]:
    """Report a library ``ValueError`` as one line that starts with the input's path (or
    "A against B" for two)."""
    try:
        yield
    except ValueError as error:
        if len(paths) == 1:
            raise UsageError(str(error), paths[0]) from None
        raise UsageError(f"{' against '.join(paths)}: {error}") from None


def optimize(args: argparse.Namespace) -> int:
    _refuse_to_overwrite(args.input, args.output, args.overwrite)
    _refuse_to_overwrite(args.input, args.covariances, args.overwrite)
    _check_output(args.output)
    _check_output(args.plot, figure=True)
    _check_output(args.covariances, text=True)
    _check_drop_rejected(args)
    inputs = _Inputs(args)
    read = inputs.graph(args.input)
    graph = read.graph
    if args.fix:
        try:
            graph.fix(args.fix)
        except KeyError as error:
            raise UsageError(f"--fix: {error.args[0]}") from None
    _check_writable(args.input, graph, args.output)
    before = graph.copy()
    with Progress(_talks(args), args.solver) as progress:
        with _about(args.input):  # values the initialisation cannot hold, say
            result = posegraph.optimize(graph, callback=progress, **_solving(args))
    summary = result.summary
    _note_interruption(progress, summary)
    if not math.isfinite(summary.final_error):
        raise UsageError(
            f"the optimisation ended with error {summary.final_error} (at the file's values: "
            f"{summary.input_error}); numbers this large overflow in double precision. Nothing "
            "written",
            args.input,
        )
    graph.set_values(result.values)
    covariances = _covariances(args.input, graph) if args.covariances else None
    output, wrote = _output_graph(args, graph)
    if args.output:
        convert_graph(
            output,
            args.output,
            g2o_rotation_information=args.g2o_rotation_information,
            sim3_dialect=read.sim3_dialect or "a",
        )
    if args.plot:
        from posegraph.plotting import plot_graphs

        plot_graphs(
            [("initial", before), ("optimised", graph)],
            args.plot,
            title=os.path.basename(args.input),
        )
    if args.covariances:
        write_covariances(args.covariances, graph.group.__name__, graph.node_ids, covariances)
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
        "summary": summary.as_dict(),
        "skipped_lines": inputs.skipped_lines,
    }
    written = {"wrote": wrote, "plotted": args.plot, "covariances": args.covariances}
    text = format_summary(args.input, graph, summary, written, read.lifted_scale_information)
    _emit(args, record, text)
    return EXIT_OK if summary.converged else EXIT_NOT_CONVERGED


def _solving(args: argparse.Namespace) -> dict:
    """``optimize``'s keyword arguments from the solving options (``--solver``, ``--init``,
    ``--robust…``, ``--max-iterations``, ``--time-limit``)."""
    return {
        "init": args.init,
        "options": SolverOptions(
            method=args.solver, max_iterations=args.max_iterations, time_limit=args.time_limit
        ),
        "robust": args.robust,
        "robust_edges": args.robust_edges,
        "robust_priors": args.robust_priors,
    }


def _note_interruption(progress: Progress, summary: Summary) -> None:
    """A run that Ctrl-C stopped did not converge, whatever its last iteration said."""
    if progress.interrupted:
        summary.termination = "interrupted (Ctrl-C)"
        summary.converged = False


def _covariances(source: str, graph: posegraph.PoseGraph) -> np.ndarray:
    """Every node's marginal covariance at the graph's values, before anything is written."""
    try:
        return posegraph.marginals(graph, graph.node_ids, require_measured=True)
    except NotPositiveDefinite as error:
        raise UsageError(
            f"{error}. Nothing written (without --covariances, the optimised graph is)", source
        ) from None


def info(args: argparse.Namespace) -> int:
    inputs = _Inputs(args, warn_skipped=False)  # the report lists the skipped lines as a problem
    diagnosis = diagnose(inputs.graph(args.input))
    record = {"command": "info", **diagnosis.as_dict(), "skipped_lines": inputs.skipped_lines}
    _emit(args, record, format_diagnosis(diagnosis))
    return EXIT_OK


def convert(args: argparse.Namespace) -> int:
    _refuse_to_overwrite(args.input, args.output, args.overwrite)
    _check_output(args.output, args.to, remedy="; say --to g2o|toro|tum|kitti")
    inputs = _Inputs(args)
    graph = inputs.graph(args.input).graph
    _check_writable(args.input, graph, args.output, to=args.to)
    written = convert_graph(
        graph, args.output, args.to, args.sim3_dialect, args.g2o_rotation_information
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
    _emit(args, record, f"wrote {args.output} ({written}, {graph.num_nodes} poses)")
    return EXIT_OK


def plot(args: argparse.Namespace) -> int:
    from posegraph.plotting import plot_graphs

    _check_output(args.output, figure=True)
    inputs = _Inputs(args)
    graphs = [(os.path.basename(p), inputs.graph(p).graph) for p in args.inputs]
    plot_graphs(graphs, args.output, title=args.title, view=args.view)
    record = {
        "command": "plot",
        "inputs": args.inputs,
        "output": args.output,
        "skipped_lines": inputs.skipped_lines,
    }
    _emit(args, record, f"wrote {args.output}")
    return EXIT_OK


def eval(args: argparse.Namespace) -> int:  # noqa: A001 - the subcommand's name
    _check_output(args.plot, figure=True)
    inputs = _Inputs(args)
    estimate = inputs.trajectory(args.estimate)
    truth = inputs.trajectory(args.ground_truth)
    with _about(args.estimate, args.ground_truth):  # they do not pair, say
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
    _emit(args, record, format_evaluation(evaluation))
    return EXIT_OK


NO_SIM3_EDGE = (
    "no Sim3 edge: each loop closure only says that its ends share one scale, which corrects"
    " scale drift only where its translation is metric; Sim3 loop closures (EDGE_SIM3:EXPMAP)"
    " carry the scale change"
)


def scale_drift(args: argparse.Namespace) -> int:
    from posegraph.scale_drift import correct_scale_drift
    from posegraph.trajectory_io import write_trajectory

    _refuse_to_overwrite(args.input, args.output, args.overwrite)
    _check_output(args.output)
    _check_output(args.plot, figure=True)
    _check_drop_rejected(args)
    inputs = _Inputs(args)
    read = inputs.graph(args.input)
    graph = read.graph
    if graph.group is posegraph.SE3 and _talks(args):
        warn(f"{args.input}: {NO_SIM3_EDGE}")
    if graph.group is not posegraph.SE2:  # refused below, by the correction
        _check_writable(args.input, graph, args.output, group=posegraph.Sim3)
    truth = inputs.trajectory(args.gt) if args.gt else None  # read before the work
    before = Trajectory.of_graph(graph)
    with Progress(_talks(args), args.solver) as progress:
        with _about(args.input):  # a graph it cannot correct (SE2), values beyond doubles
            correction = correct_scale_drift(
                graph, args.scale_information, args.convention, callback=progress, **_solving(args)
            )
    summary = correction.result.summary
    _note_interruption(progress, summary)
    # Lifted by the reader (a file mixing SE3 and Sim3) or by the correction (SE3 only).
    lifted = read.lifted_scale_information
    if lifted is None:
        lifted = correction.lifted_scale_information
    after = Trajectory.of_graph(correction.graph, correction.poses)  # as asked for
    corrected = Trajectory.of_graph(correction.graph)  # world-from-camera
    output, wrote = _output_graph(args, correction.graph)
    if args.output:
        written = output_format(args.output)
        if written in ("tum", "kitti"):
            write_trajectory(after, args.output, written)
        else:
            convert_graph(output, args.output, written, sim3_dialect=read.sim3_dialect or "a")
    ate = None
    if truth is not None:
        ate = tuple(evaluate(poses, truth, "se3").ate.rmse for poses in (before, corrected))
    if args.plot:
        from posegraph.plotting import plot_trajectories

        curves = [("before", before.positions), ("corrected", corrected.positions)]
        if truth is not None:
            curves.append(("ground truth", truth.positions))
        title = f"scale-drift correction: {os.path.basename(args.input)} (top view)"
        plot_trajectories(curves, args.plot, title=title, view="top")
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
        "summary": summary.as_dict(),
        "ate_before": ate[0] if ate else None,
        "ate_after": ate[1] if ate else None,
        "skipped_lines": inputs.skipped_lines,
    }
    written = {"wrote": wrote, "plotted": args.plot}
    text = format_scale_drift(args.input, correction, ate, written, lifted)
    _emit(args, record, text)
    return EXIT_OK if summary.converged else EXIT_NOT_CONVERGED


def bench(args: argparse.Namespace) -> int:
    from posegraph.benchmarks.optimizer import benchmark_files, run

    files = benchmark_files()
    if args.graphs:
        files = [f for f in files if f.stem in args.graphs]
    if not files:
        raise UsageError("no benchmark graphs found (../shared/datasets or gtsam's Data/)")
    table = run(files, args.repeats, args.rounds, args.budget, _talks(args), args.solver)
    if args.json:
        print(json.dumps({"command": "bench", "solver": args.solver, "table": table}, indent=2))
    elif not args.quiet:
        sys.stdout.flush()
    return EXIT_OK
