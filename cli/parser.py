"""The ``posegraph`` command's argument parser: shared option groups, and one small builder
per subcommand."""

from __future__ import annotations

import argparse
from typing import NamedTuple

import posegraph
from posegraph.benchmarks.optimizer import METHODS as BENCHMARK_METHODS
from posegraph.benchmarks.timing import add_timing_arguments, at_least
from posegraph.trajectory.evaluation import KITTI_SEGMENT_LENGTHS, MAX_KEY_DIFFERENCE

from . import options
from .examples import EXAMPLES

PLOT_MODES = ("xy", "xz", "yz", "xyz")
"""``eval --plot-mode``: ``posegraph.plotting.PLOT_MODES``, named here so that the parser does
not import matplotlib."""

ODOMETRY_SIGMAS = (0.1, 0.01)
"""``convert``'s default standard deviations of a trajectory's odometry edges."""

GENERATED = ("sphere", "grid", "manhattan", "monocular", "false-loops")
"""What ``generate`` makes."""


class _Groups(NamedTuple):
    """The option groups that subcommands share (argparse parents)."""

    common: argparse.ArgumentParser
    reading: argparse.ArgumentParser
    solving: argparse.ArgumentParser


class _Version(argparse.Action):
    """``--version``: the installed version, looked up only when asked for."""

    def __call__(self, parser: argparse.ArgumentParser, *_) -> None:
        print(f"posegraph {posegraph.__version__}")
        parser.exit()


def parser() -> argparse.ArgumentParser:
    """The whole parser: the shared groups, then each subcommand's builder."""
    top = argparse.ArgumentParser(
        prog="posegraph",
        description="Pose-graph optimisation on Lie groups (SE2, SE3, Sim3).",
        epilog="Run 'posegraph COMMAND --help' for a command's options and examples.",
    )
    top.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    groups = _Groups(options.common(), options.reading(), options.solving())
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (
        _optimize,
        _info,
        _convert,
        _plot,
        _eval,
        _scale_drift,
        _certify,
        _bench,
        _generate,
        _datasets,
    ):
        add(sub, groups)
    return top


ALIASES = {"optimize": ["optimise"]}
"""Other spellings of a command (British English)."""


def _command(sub, name: str, help_text: str, parents) -> argparse.ArgumentParser:
    command = sub.add_parser(
        name,
        aliases=ALIASES.get(name, []),
        help=help_text,
        description=help_text,
        parents=parents,
        epilog=EXAMPLES[name],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    command.set_defaults(command=name)  # an alias runs, and reports as, the command
    return command


def _optimize(sub, groups: _Groups) -> None:
    """``optimize``."""
    opt = _command(
        sub,
        "optimize",
        "optimise a g2o or TORO pose graph",
        [groups.common, groups.reading, groups.solving],
    )
    opt.add_argument("input", help="g2o or TORO file")
    opt.add_argument(
        "-o", "--output", help="write the optimised graph, or its poses, here (format by suffix)"
    )
    options.output_format(opt)
    opt.add_argument(
        "--covariances",
        metavar="FILE",
        help="write every pose's marginal covariance at the optimum here (text: id, then the "
        "upper triangle over the tangent; README)",
    )
    opt.add_argument(
        "--fix", type=int, nargs="+", metavar="ID", default=[], help="hold these nodes"
    )
    opt.add_argument("--plot", metavar="FIG.png", help="before/after figure")
    opt.add_argument(
        "--calibrate-noise",
        action="store_true",
        help="scale each class's information (odometry, loops, priors) to its inliers' residuals"
        " and solve again; --robust gnc does so where it kept gross outliers (measurements that"
        " fail the chi2 test tenfold under the noise the residuals show). -o's graph holds the"
        " scaled information",
    )
    opt.add_argument(
        "--certify",
        action="store_true",
        help="check the result's global optimality on SE-Sync's isotropic problem (SE2 and "
        "SE3 graphs without priors; see 'posegraph certify')",
    )
    opt.add_argument(
        "--overwrite",
        action="store_true",
        help="allow -o or --covariances to be the input file",
    )


def _info(sub, groups: _Groups) -> None:
    """``info``."""
    info = _command(
        sub,
        "info",
        "inspect a graph: counts, gauge, information checks, problems",
        [groups.common, groups.reading],
    )
    info.add_argument("input")
    info.add_argument(
        "--certify",
        action="store_true",
        help="also optimise a copy and check its global optimality (see 'posegraph certify')",
    )


def _convert(sub, groups: _Groups) -> None:
    """``convert``."""
    conv = _command(
        sub,
        "convert",
        "convert g2o <-> TORO, export poses as TUM or KITTI, or make a graph of a trajectory",
        [groups.common, groups.reading],
    )
    conv.add_argument("input")
    conv.add_argument("output")
    options.output_format(conv)
    conv.add_argument(
        "--sigmas",
        type=float,
        nargs=2,
        default=list(ODOMETRY_SIGMAS),
        metavar=("TRANSLATION", "ROTATION"),
        help="a trajectory converted to a graph: the standard deviations of its odometry edges,"
        " in the trajectory's unit and in radians (default %(default)s)",
    )
    conv.add_argument("--sim3-dialect", choices=["a", "b"], default="a", help="for Sim3 g2o output")
    conv.add_argument("--overwrite", action="store_true", help="allow the output to be the input")


def _plot(sub, groups: _Groups) -> None:
    """``plot``."""
    plot = _command(
        sub,
        "plot",
        "draw graphs and trajectories (TUM, KITTI, EuRoC), one or overlaid",
        [groups.common, groups.reading],
    )
    plot.add_argument("inputs", nargs="+", metavar="input")
    plot.add_argument("-o", "--output", required=True, metavar="FIG.png")
    plot.add_argument("--view", choices=["auto", "top", "3d"], default="auto")
    plot.add_argument("--title")


def _eval(sub, groups: _Groups) -> None:
    """``eval``."""
    ev = _command(
        sub,
        "eval",
        "ATE, RPE and KITTI drift of an estimate against ground truth",
        [groups.common, groups.reading],
    )
    ev.add_argument("estimate", help="g2o, TORO, TUM, KITTI or EuRoC (.csv)")
    ev.add_argument("ground_truth", help="g2o, TORO, TUM, KITTI or EuRoC (.csv)")
    ev.add_argument("--align", choices=["se3", "sim3", "none"], default="se3", help="default: se3")
    ev.add_argument("--delta", type=at_least(1), default=1, help="RPE step in poses (default 1)")
    ev.add_argument(
        "--max-time-difference",
        type=at_least(0, float),
        default=MAX_KEY_DIFFERENCE,
        metavar="SECONDS",
        help=f"pair poses whose time stamps differ by at most this (default {MAX_KEY_DIFFERENCE}, "
        "as the TUM benchmark's associate.py); node ids and KITTI lines pair when equal",
    )
    ev.add_argument(
        "--segment-lengths",
        type=float,
        nargs="+",
        default=list(KITTI_SEGMENT_LENGTHS),
        metavar="LENGTH",
        help="path lengths of the drift's segments, in the trajectories' unit (default the KITTI"
        " benchmark's 100 200 … 800)",
    )
    ev.add_argument(
        "--match-by-index",
        action="store_true",
        help="pair the k-th pose of the estimate with the k-th of the ground truth, over the"
        " shorter (KITTI files of different lengths are refused without it)",
    )
    ev.add_argument(
        "--plot",
        metavar="FIG.png",
        help="the ground truth and the estimate coloured by its error, and the error over the"
        " distance travelled (as evo_ape --plot)",
    )
    ev.add_argument(
        "--plot-mode",
        choices=list(PLOT_MODES),
        default="xy",
        help="the axes the trajectories are drawn on (default xy, top-down)",
    )
    ev.add_argument(
        "--plot-colormap-max",
        type=at_least(0, float),
        metavar="ERROR",
        help="the error at the top of the colour scale (default: the largest)",
    )


def _scale_drift(sub, groups: _Groups) -> None:
    """``scale-drift``."""
    drift = _command(
        sub,
        "scale-drift",
        "correct monocular scale drift: SE3 odometry + Sim3 loop closures, optimised in Sim3",
        [groups.common, groups.reading, groups.solving],
    )
    drift.add_argument(
        "input", help="g2o with SE3 odometry and EDGE_SIM3:EXPMAP loops (or all Sim3)"
    )
    drift.add_argument(
        "-o", "--output", help=".tum/.kitti: corrected poses; .g2o: the optimised Sim3 graph"
    )
    options.output_format(drift)
    drift.add_argument(
        "--gt", metavar="GT", help="ground truth (TUM, KITTI or g2o) to report ATE before/after"
    )
    drift.add_argument(
        "--plot", metavar="FIG.png", help="trajectories before/after (and ground truth)"
    )
    drift.add_argument(
        "--convention",
        choices=["world_from_camera", "camera_from_world"],
        default="world_from_camera",
        help="pose convention of the TUM/KITTI output (default world_from_camera)",
    )
    drift.add_argument("--overwrite", action="store_true", help="allow -o to be the input file")


def _certify(sub, groups: _Groups) -> None:
    """``certify``."""
    cert = _command(
        sub,
        "certify",
        "optimise an SE2 or SE3 graph, then certify global optimality (SE-Sync's check and "
        "Riemannian staircase; exit 1 when not certified)",
        [groups.common, groups.reading, groups.solving],
    )
    cert.add_argument("input", help="g2o or TORO file (SE2 or SE3, without priors)")
    cert.add_argument(
        "-o",
        "--output",
        help="write the certified estimate, refined by posegraph's Levenberg-Marquardt, here",
    )
    options.output_format(cert)
    cert.add_argument("--overwrite", action="store_true", help="allow -o to be the input file")


def _bench(sub, groups: _Groups) -> None:
    """``bench``."""
    bench = _command(
        sub, "bench", "time posegraph against gtsam on the benchmark graphs", [groups.common]
    )
    add_timing_arguments(bench, repeats=3)
    bench.add_argument("--graphs", nargs="*", metavar="NAME", help="default: all found")
    bench.add_argument(
        "--solver",
        choices=BENCHMARK_METHODS,
        default="lm",
        help="posegraph's and gtsam's: Levenberg-Marquardt (default) or dogleg",
    )


def _generate(sub, groups: _Groups) -> None:
    """``generate``."""
    gen = _command(
        sub, "generate", "write a generated graph with its ground truth", [groups.common]
    )
    gen.add_argument(
        "kind",
        choices=GENERATED,
        help="sphere (SE3 rings on a sphere, as sphere2500), grid (SE3 cubic lattice, as"
        " smallGrid3D), manhattan (SE2 grid world, as M3500), monocular (SE3 odometry with scale"
        " drift and Sim3 loops, for scale-drift), false-loops (--from's graph with false loop"
        " closures appended)",
    )
    gen.add_argument("output", help="the graph to write (.g2o, or .graph for TORO)")
    gen.add_argument("--truth", metavar="FILE", help="also write the ground truth (.tum or .kitti)")
    gen.add_argument("--seed", type=int, default=0, help="default: 0")
    gen.add_argument(
        "--size",
        type=at_least(2),
        help="sphere: rings of 20 poses (default 10); grid: poses along each side (default 5);"
        " manhattan: cells along each side of the world (default 12)",
    )
    gen.add_argument(
        "--poses", type=at_least(2), default=300, help="manhattan, monocular: poses (default 300)"
    )
    gen.add_argument(
        "--drift",
        type=float,
        default=0.01,
        help="monocular: relative scale change per keyframe (default 0.01)",
    )
    gen.add_argument("--from", dest="source", metavar="GRAPH", help="false-loops: the graph")
    gen.add_argument(
        "--fraction",
        type=float,
        default=0.1,
        help="false-loops: their share of all loop closures (default 0.1)",
    )
    gen.add_argument(
        "--shape",
        choices=["project", "anywhere"],
        default="project",
        help="false-loops: project (random relative poses within the extent of the graph's"
        " edges, between any two nodes) or anywhere (within the map's extent, half between"
        " nodes 2-20 ids apart)",
    )


def _datasets(sub, groups: _Groups) -> None:
    """``datasets``."""
    data = _command(
        sub,
        "datasets",
        "list or download the standard benchmark graphs (SE-Sync's data/ folder)",
        [groups.common],
    )
    data.add_argument("action", choices=["list", "download"])
    data.add_argument("names", nargs="*", metavar="NAME", help="graphs to download, or all")
    data.add_argument(
        "--to",
        metavar="FOLDER",
        help="download here (default: $POSEGRAPH_DATASETS, or ~/.cache/posegraph/datasets)",
    )
