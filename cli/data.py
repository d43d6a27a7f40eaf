"""The handlers of ``generate`` (the bundled generators' graphs, written to files) and
``datasets`` (the standard benchmark graphs: where they are, and fetching them)."""

from __future__ import annotations

import argparse
from pathlib import Path

from posegraph_datasets import download as benchmark_data
from posegraph_datasets import generators, monocular, outliers
from posegraph_datasets.paths import benchmark_graph

import posegraph
from posegraph.io import load_graph
from posegraph.io.atomic import output_batch
from posegraph.io.conversion import GRAPH_FORMATS, TRAJECTORY_FORMATS, output_format
from posegraph.io.conversion import convert as convert_graph
from posegraph.io.trajectories import Trajectory, write_trajectory

from .common import check_output, check_paths, emit
from .errors import EXIT_OK, UsageError


def generate(args: argparse.Namespace) -> int:
    check_paths([args.source], {"OUTPUT": args.output, "--truth": args.truth}, None)
    check_output(args.output, remedy="; give it a .g2o or .graph suffix")
    check_output(args.truth, remedy="; give it a .tum or .kitti suffix")
    if output_format(args.output) not in GRAPH_FORMATS:
        raise UsageError("generate writes a graph: give it a .g2o or .graph suffix", args.output)
    if args.truth and output_format(args.truth) not in TRAJECTORY_FORMATS:
        raise UsageError("the ground truth is a trajectory: .tum or .kitti", args.truth)
    false_edges = 0
    with output_batch():
        if args.kind == "monocular":
            graph = _monocular(args)
        elif args.kind == "false-loops":
            graph, false_edges = _false_loops(args)
        else:
            graph, truth = _generated(args)
            convert_graph(graph, args.output)
            if args.truth:
                trajectory = Trajectory.of_graph(graph, truth)
                write_trajectory(trajectory, args.truth, output_format(args.truth))
    record = {
        "command": "generate",
        "kind": args.kind,
        "output": args.output,
        "truth": args.truth,
        "nodes": graph.num_nodes,
        "edges": graph.num_edges,
        "false_edges": false_edges,
    }
    text = f"wrote {args.output} ({graph.num_nodes} poses, {graph.num_edges} edges"
    if false_edges:
        text += f"; its last {false_edges} edges are the false loops"
    text += f"){f' and {args.truth}' if args.truth else ''}"
    emit(args, record, text)
    return EXIT_OK


def _generated(args: argparse.Namespace) -> tuple[posegraph.PoseGraph, posegraph.SE3]:
    """The graph and ground truth of ``sphere``, ``grid`` or ``manhattan``."""
    if args.kind == "sphere":
        return generators.sphere(rings=args.size or 10, poses_per_ring=20, seed=args.seed)
    if args.kind == "grid":
        return generators.grid(size=args.size or 5, seed=args.seed)
    grid_size = args.size or 12
    return generators.manhattan_world(num_poses=args.poses, grid_size=grid_size, seed=args.seed)


def _monocular(args: argparse.Namespace) -> posegraph.PoseGraph:
    """A monocular sequence (``posegraph_datasets.monocular``): its g2o file, and the ground
    truth where asked."""
    if output_format(args.output) != "g2o":
        raise UsageError("a monocular sequence has Sim3 loops, which only g2o holds", args.output)
    sequence = monocular.monocular_sequence(num_poses=args.poses, drift=args.drift, seed=args.seed)
    truth_format = output_format(args.truth) if args.truth else "tum"
    monocular.write_sequence(sequence, args.output, args.truth, truth_format=truth_format)
    return sequence.sim3_graph()


def _false_loops(args: argparse.Namespace) -> tuple[posegraph.PoseGraph, int]:
    """``--from``'s graph with false loops appended (``posegraph_datasets.outliers``)."""
    if args.source is None:
        raise UsageError("false-loops adds false loop closures to a graph: name it with --from")
    if args.truth:
        raise UsageError("false-loops has no ground truth to write (--truth)")
    graph = load_graph(args.source).graph
    add = (
        outliers.add_false_loops_anywhere if args.shape == "anywhere" else outliers.add_false_loops
    )
    try:
        corrupted, false = add(graph, args.fraction, args.seed)
    except ValueError as error:
        raise UsageError(f"--fraction: {error}") from None
    convert_graph(corrupted, args.output)
    return corrupted, int(false.sum())


def datasets(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list(args)
    names = benchmark_data.GRAPHS if args.names == ["all"] else args.names
    if not names:
        raise UsageError("name the graphs to download (or all)")
    try:
        files = [benchmark_data.graph_name(name) for name in names]
    except benchmark_data.DownloadError as error:
        raise UsageError(str(error)) from None
    folder = benchmark_data.download_dir() if args.to is None else Path(args.to)
    fetched = []
    for file in files:
        path, new = benchmark_data.download(file, folder)
        fetched.append({"name": file, "path": str(path), "downloaded": new})
        if not (args.json or args.quiet):
            print(f"{'fetched' if new else 'already there:'} {path}")
    record = {"command": "datasets", "action": "download", "folder": str(folder), "graphs": fetched}
    emit(args, record, f"{len(files)} graph(s) in {folder}; SHA-256 checked")
    return EXIT_OK


def _list(args: argparse.Namespace) -> int:
    graphs = []
    for file in benchmark_data.GRAPHS:
        path = benchmark_graph(file)
        graphs.append({"name": file, "path": None if path is None else str(path)})
    lines = [f"{g['name']:<30} {g['path'] or '-'}" for g in graphs]
    lines.append(
        f"fetch with 'posegraph datasets download NAME|all' (into {benchmark_data.download_dir()})"
    )
    emit(args, {"command": "datasets", "action": "list", "graphs": graphs}, "\n".join(lines))
    return EXIT_OK
