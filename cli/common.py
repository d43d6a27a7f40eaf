"""What every subcommand shares: its read options and inputs, the checks of its outputs
before any work, the solving options, and how it prints (text or one JSON document)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
from collections.abc import Iterator

import numpy as np

import posegraph
from posegraph.io import ReadOptions, ReadResult, load_graph
from posegraph.io.atomic import check_replaceable, is_special
from posegraph.io.conversion import GRAPH_FORMATS, load_trajectory, output_format, unwritable_to
from posegraph.io.trajectories import Trajectory
from posegraph.io.writer import Rejected
from posegraph.lie import LieGroup
from posegraph.solvers import SolverOptions, Summary

from .errors import UsageError, warn
from .progress import LEAST_SQUARES, Progress

Kept = tuple[np.ndarray, np.ndarray]
"""Masks over a file's between edges and priors of those solved (not set aside)."""


def read_options(args: argparse.Namespace) -> ReadOptions:
    return ReadOptions(
        lenient=args.lenient,
        g2o_rotation_information=args.g2o_rotation_information,
        identity_information=args.identity_information,
        edge2_order=args.edge2_order,
        repair_information=args.repair_information,
        scale_information=args.scale_information,
    )


class Inputs:
    """A command's input files, read with its options. What lenient reading skipped is kept for
    the JSON document (``skipped_lines``) and, with ``warn_skipped``, as a warning (``warn``)
    that ``emit`` prints before the results, which leave out what those lines say (a node
    whose vertex line was skipped keeps its edges). A command that stops prints its one line
    of error alone."""

    def __init__(
        self, args: argparse.Namespace, warn_skipped: bool = True, lenient: bool = False
    ) -> None:
        self.options = read_options(args)
        if lenient:
            self.options = dataclasses.replace(self.options, lenient=True)
        self.warn_skipped = warn_skipped
        self.skipped_lines: list[dict] = []
        self.warnings: list[str] = []

    def warn(self, message: str) -> None:
        """A finding about the inputs, for ``emit`` to print (text mode) with the results."""
        self.warnings.append(message)

    def graph(self, path: str) -> ReadResult:
        read = load_graph(path, self.options)
        self.skipped_lines += [
            {"path": path, "reason": why, "count": count, "first_line": line}
            for why, count, line in read.skipped_by_reason()
        ]
        if read.skipped and self.warn_skipped:
            report = read.skipped_report()
            self.warn(f"{path}: {report}; the results leave out what those lines say")
        return read

    def trajectory(self, path: str) -> Trajectory:
        return load_trajectory(path, self.graph)


def reading_record(read: ReadResult, args: argparse.Namespace) -> dict:
    """How the information was read (``schema._READING``): the matrices repaired, and the
    weighting of SE3 and Sim3 rotation information."""
    rotation = None
    if read.graph.group is not posegraph.SE2:
        rotation = "quaternion" if args.g2o_rotation_information else "phi"
    return {"repaired_information": read.repaired_information, "rotation_information": rotation}


def json_safe(value):
    """``value`` with every float that is not finite as None (JSON has no NaN or ∞)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(item) for item in value]
    return value


def talks(args: argparse.Namespace) -> bool:
    """Whether the command reports as text on the terminal: neither ``--json`` nor ``--quiet``
    (progress and warnings are shown then)."""
    return not (args.json or args.quiet)


def reports(args: argparse.Namespace) -> bool:
    """Whether the command prints its results (``emit``): as JSON, or as text unless
    ``--quiet``. What only the report holds is not computed otherwise."""
    return args.json or not args.quiet


def emit(args: argparse.Namespace, record: dict, text: str, warnings: list[str] = ()) -> None:
    """Print the results: the JSON document, or the ``warnings`` (on stderr) and the text."""
    if args.json:
        print(json.dumps(json_safe(record), indent=2, allow_nan=False))
    elif not args.quiet:
        for message in warnings:
            warn(message)
        print(text)


def _same_file(first: str, second: str) -> bool:
    """Whether two paths name one file: the same path once links are followed, or a hard link
    to it. Devices and FIFOs are written through, so two uses of one are not a clash."""
    if is_special(first) or is_special(second):
        return False
    if os.path.realpath(first) == os.path.realpath(second):
        return True
    return os.path.exists(first) and os.path.exists(second) and os.path.samefile(first, second)


def check_paths(reads: list[str], writes: dict[str, str | None], overwrite: bool | None) -> None:
    """Refuse, before any work, an output (flag → path) that is another output or an input.
    ``-o`` may replace the first input (the graph) when ``overwrite`` (``--overwrite``) is set;
    None: the command has no such option."""
    outputs = [(flag, path) for flag, path in writes.items() if path]
    for k, (flag, path) in enumerate(outputs):
        for earlier_flag, earlier in outputs[:k]:
            if _same_file(path, earlier):
                raise UsageError(f"{earlier_flag} and {flag} name the same file", path)
        for k, source in enumerate(reads):
            allowed = flag == "-o" and k == 0
            if not source or not _same_file(source, path) or (allowed and overwrite):
                continue
            advice = "; pass --overwrite to allow it" if allowed and overwrite is False else ""
            raise UsageError(f"refusing to overwrite an input file with {flag}{advice}", path)


def check_output(
    path: str | None,
    to: str | None = None,
    figure: bool = False,
    text: bool = False,
    remedy: str = "",
    interactive: bool = False,
) -> None:
    """Fail before any work if ``path`` cannot be written: a format not known by its suffix
    (or ``to``; a ``figure``'s by matplotlib, or ``.html`` where it is ``interactive``; ``text``
    has one format; ``remedy`` follows that refusal), a folder that does not exist, or a
    read-only file."""
    if path is None:
        return
    try:
        if figure:
            from posegraph.plotting import check_figure_path

            check_figure_path(path, interactive)
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


def check_drop_rejected(args: argparse.Namespace) -> None:
    """``--drop-rejected`` needs a robust run, and a graph file to leave its rejections out of."""
    if not args.drop_rejected:
        return
    if args.robust is None:
        raise UsageError("--drop-rejected needs --robust: only a robust run rejects measurements")
    if args.output is None or output_format(args.output, args.to) not in GRAPH_FORMATS:
        raise UsageError(
            "--drop-rejected leaves the rejected edges out of the graph that -o writes: give -o a"
            " g2o or TORO file",
            args.output,
        )


def set_aside_rejected(read: ReadResult, readmit: bool) -> tuple[posegraph.PoseGraph, Kept | None]:
    """The graph to solve: the file's without the measurements that its lines mark rejected (a
    robust run's output), unless ``readmit`` (``--readmit-rejected``); and the masks of the
    edges and priors kept (None if none was set aside)."""
    if read.rejected is None or readmit:
        return read.graph, None
    edges, priors = read.rejected
    graph = read.graph.with_edges(~edges)
    graph.remove_priors(priors)
    return graph, (~edges, ~priors)


def output_graph(
    args: argparse.Namespace,
    smoother: posegraph.Smoother,
    source: posegraph.PoseGraph,
    kept: Kept | None,
) -> tuple[posegraph.PoseGraph, Rejected | None, str | None]:
    """The graph that ``-o`` gets, the masks of its measurements to mark rejected, and how the
    report names the file. The solved values go on the file's graph ``source`` (lifted to the
    solved group), every measurement in its order: those set aside (``kept`` False) and those
    the robust run rejected are marked. With ``--drop-rejected``, the inliers alone."""
    graph = smoother.graph
    if args.drop_rejected:
        inliers = smoother.without_rejected()
        left_out = f"{graph.num_edges - inliers.num_edges} rejected edge(s)"
        if len(inliers.priors) < len(graph.priors):
            left_out += f" and {len(graph.priors) - len(inliers.priors)} rejected prior(s)"
        return inliers, None, f"{args.output} (without the {left_out})"
    edges, priors = smoother.rejected()
    if kept is not None:
        full = source.copy()
        full.set_values(graph.values, check=False)
        full.fixed = graph.fixed.copy()
        edges, priors = _spread(edges, kept[0]), _spread(priors, kept[1])
        graph = full
    if not (edges.any() or priors.any()) or args.output is None:
        return graph, None, args.output
    marked = np.count_nonzero(edges) + np.count_nonzero(priors)
    return graph, (edges, priors), f"{args.output} ({marked} marked rejected)"


def _spread(rejected: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """A mask over all measurements: those not ``kept``, and the kept ones ``rejected``."""
    spread = ~kept
    spread[kept] = rejected
    return spread


def check_writable(
    source: str,
    graph: posegraph.PoseGraph,
    path: str | None,
    to: str | None = None,
    group: type[LieGroup] | None = None,
) -> None:
    """Fail before any work if the graph read from ``source`` (lifted to ``group``, if given)
    cannot be written to ``path`` as ``to`` (``posegraph.io.conversion.unwritable_to``)."""
    reason = None if path is None else unwritable_to(graph, path, to, group)
    if reason is not None:
        raise UsageError(reason, source)


@contextlib.contextmanager
def about(*paths: str) -> Iterator[None]:
    """Report a library ``ValueError`` as one line that starts with the input's path (or
    "A against B" for two)."""
    try:
        yield
    except ValueError as error:
        if len(paths) == 1:
            raise UsageError(str(error), paths[0]) from None
        raise UsageError(f"{' against '.join(paths)}: {error}") from None


def solving_options(args: argparse.Namespace) -> dict:
    """``optimize``'s keyword arguments from the solving options (``--solver``, ``--init``,
    ``--robust…``, ``--max-iterations``, ``--time-limit``)."""
    robust = None
    if args.robust is not None:
        try:
            robust = posegraph.RobustSpec.parse(args.robust, args.robust_edges, args.robust_priors)
        except ValueError as error:
            raise UsageError(f"--robust: {error}") from None
    options = SolverOptions(
        method=args.solver, max_iterations=args.max_iterations, time_limit=args.time_limit
    )
    return {"init": args.init, "options": options, "robust": robust}


def cost_label(args: argparse.Namespace) -> str:
    """How progress names the cost of a solve that has no stage: least squares', or an
    M-estimator's ½Σρ."""
    if args.robust is None or args.robust.startswith("gnc"):
        return LEAST_SQUARES
    return "½Σ ρ"


def noting_interruption(progress: Progress, summary: Summary) -> Summary:
    """The summary, saying that a run that Ctrl-C stopped did not converge, whatever its last
    iteration said."""
    if not progress.interrupted:
        return summary
    return dataclasses.replace(summary, termination="interrupted (Ctrl-C)", converged=False)
