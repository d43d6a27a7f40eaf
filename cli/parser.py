"""The ``posegraph`` command's argument parser: shared option groups, and one small builder
per subcommand."""

from __future__ import annotations

import argparse
from typing import NamedTuple

import posegraph
from posegraph.benchmarks.optimizer import METHODS as BENCHMARK_METHODS
from posegraph.benchmarks.timing import add_timing_arguments, at_least
from posegraph.init.choice import INITIALIZERS
from posegraph.io.tags import EDGE2_ORDERS
from posegraph.solvers.options import METHODS
from posegraph.trajectory.evaluation import KITTI_SEGMENT_LENGTHS, MAX_KEY_DIFFERENCE

EXAMPLES = {
    "optimize": """examples:
  posegraph optimize datasets/sphere_small.g2o -o optimised.g2o --plot optimised.png
  posegraph optimize city.graph -o city.g2o --init odometry --max-iterations 50 --json
  posegraph optimize garage.g2o -o out.g2o --fix 0 17 --g2o-rotation-information
  posegraph optimize intel.g2o -o out.g2o --robust gnc --covariances covariances.txt
  posegraph optimize false_loops.g2o -o inliers.g2o --robust gnc --drop-rejected --plot gnc.png""",
    "info": """examples:
  posegraph info datasets/manhattan_small.g2o
  posegraph info broken.g2o --lenient --json""",
    "convert": """examples:
  posegraph convert intel.g2o intel.graph          # g2o -> TORO
  posegraph convert sphere.g2o sphere.tum          # poses as TUM: id tx ty tz qx qy qz qw
  posegraph convert sphere.g2o poses.txt --to kitti""",
    "plot": """examples:
  posegraph plot before.g2o after.g2o -o overlay.png
  posegraph plot garage.g2o -o top.png --view top""",
    "eval": """examples:
  posegraph eval optimised.g2o groundtruth.tum
  posegraph eval estimate.tum groundtruth.tum --align sim3 --plot ate.png --json
  posegraph eval KeyFrameTrajectory.txt groundtruth.txt --align sim3 --max-time-difference 0.01""",
    "scale-drift": """examples:
  python -m posegraph_datasets.monocular monocular.g2o groundtruth.tum  # a generated sequence
  posegraph scale-drift monocular.g2o -o corrected.tum --gt groundtruth.tum --plot drift.png
  posegraph scale-drift monocular.g2o -o corrected.g2o --convention camera_from_world --json
  posegraph scale-drift place_recognition.g2o -o corrected.tum --robust gnc  # false loops""",
    "bench": """examples:
  posegraph bench --graphs sphere2500 parking-garage --repeats 3
  posegraph bench --solver dogleg --json""",
}


class _Groups(NamedTuple):
    """The option groups that subcommands share (argparse parents)."""

    common: argparse.ArgumentParser
    reading: argparse.ArgumentParser
    solving: argparse.ArgumentParser


def parser() -> argparse.ArgumentParser:
    """The whole parser: the shared groups, then each subcommand's builder."""
    top = argparse.ArgumentParser(
        prog="posegraph",
        description="Pose-graph optimisation on Lie groups (SE2, SE3, Sim3).",
        epilog="Run 'posegraph COMMAND --help' for a command's options and examples.",
    )
    top.add_argument("--version", action="version", version=f"posegraph {posegraph.__version__}")
    groups = _Groups(_common(), _reading(), _solving())
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_optimize, _info, _convert, _plot, _eval, _scale_drift, _bench):
        add(sub, groups)
    return top


def _command(sub, name: str, help_text: str, parents) -> argparse.ArgumentParser:
    return sub.add_parser(
        name,
        help=help_text,
        description=help_text,
        parents=parents,
        epilog=EXAMPLES[name],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def _common() -> argparse.ArgumentParser:
    """Options of every command: the output's form."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--json", action="store_true", help="print one JSON document (README: schema)"
    )
    common.add_argument("--quiet", action="store_true", help="print nothing but errors")
    common.add_argument("--debug", action="store_true", help="show tracebacks")
    return common


def _reading() -> argparse.ArgumentParser:
    """Options of every command that reads files."""
    reading = argparse.ArgumentParser(add_help=False)
    reading.add_argument(
        "--lenient",
        action="store_true",
        help="skip bad lines instead of stopping (a warning, or skipped_lines in --json, lists them)",
    )
    reading.add_argument(
        "--g2o-rotation-information",
        action="store_true",
        help="weigh SE3 rotation information as g2o does (Λ_φφ = Λ_qq/4)",
    )
    reading.add_argument(
        "--identity-information",
        action="store_true",
        help="weigh every edge and prior by the identity, ignoring the file's information "
        "(as TORO's -ic); lines may then omit it",
    )
    reading.add_argument(
        "--edge2-order",
        choices=list(EDGE2_ORDERS),
        default="toro",
        help="order of the information values on EDGE2 lines: toro (I11 I12 I22 I33 I13 I23, "
        "default) or g2o (I11 I12 I13 I22 I23 I33, as gtsam's readG2o reads them)",
    )
    reading.add_argument(
        "--repair-information",
        choices=["psd", "isotropic"],
        help="repair information matrices instead of refusing them: psd clips the eigenvalues of"
        " those not positive semi-definite; isotropic gives every measurement SE-Sync's model"
        " (one translation and one rotation precision)",
    )
    reading.add_argument(
        "--scale-information",
        type=float,
        help="information on log-scale of SE3 edges lifted to Sim3, in files mixing SE3 and Sim3 "
        "lines (and, for scale-drift, in SE3 files): 1/σ², σ the relative scale drift per edge "
        "(default: from their translation information, or the scale change the Sim3 loops "
        "call for where that is larger; the reports show it)",
    )
    return reading


def _solving() -> argparse.ArgumentParser:
    """Options of the commands that optimise."""
    solving = argparse.ArgumentParser(add_help=False)
    solving.add_argument(
        "--solver",
        choices=METHODS,
        default="lm",
        help="lm (Levenberg-Marquardt, default), gn (Gauss-Newton) or dogleg (Powell's, in a"
        " trust region: one factorisation per linearisation)",
    )
    solving.add_argument(
        "--init",
        choices=INITIALIZERS,
        default="auto",
        help="default: auto (chordal relaxation when the graph has loops, else odometry)",
    )
    solving.add_argument(
        "--robust",
        metavar="KERNEL[:WIDTH]",
        help="gnc (truncated least squares by graduated non-convexity), huber, cauchy, "
        "geman-mcclure, tukey or dcs; width in Mahalanobis units (default √χ²_k(0.999) for "
        "gnc, √χ²_k(0.95) for the others, k the directions a measurement weighs: 3 for an SE3 "
        "position-only fix)",
    )
    solving.add_argument(
        "--robust-edges",
        choices=["loops", "all"],
        default="loops",
        help="edges the kernel applies to (default: loops, i.e. not between consecutive nodes)",
    )
    solving.add_argument(
        "--robust-priors",
        action="store_true",
        help="apply the kernel to the priors too (absolute fixes such as GNSS)",
    )
    solving.add_argument(
        "--drop-rejected",
        action="store_true",
        help="leave the edges and priors that --robust rejected out of -o's graph (g2o or TORO);"
        " without it they are written commented out, marked rejected",
    )
    solving.add_argument(
        "--readmit-rejected",
        action="store_true",
        help="solve with the edges and priors that the file marks rejected (by default they are"
        " set aside, as the robust run that marked them did, and written back marked)",
    )
    solving.add_argument("--max-iterations", type=at_least(0), default=100, help="default: 100")
    solving.add_argument("--time-limit", type=at_least(0, float), help="seconds")
    return solving


def _optimize(sub, groups: _Groups) -> None:
    """``optimize``."""
    opt = _command(
        sub,
        "optimize",
        "optimise a g2o or TORO pose graph",
        [groups.common, groups.reading, groups.solving],
    )
    opt.add_argument("input", help="g2o or TORO file")
    opt.add_argument("-o", "--output", help="write the optimised graph here (format by suffix)")
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


def _convert(sub, groups: _Groups) -> None:
    """``convert``."""
    conv = _command(
        sub,
        "convert",
        "convert g2o <-> TORO, or export poses as TUM or KITTI",
        [groups.common, groups.reading],
    )
    conv.add_argument("input")
    conv.add_argument("output")
    conv.add_argument("--to", choices=["g2o", "toro", "tum", "kitti"], help="default: by suffix")
    conv.add_argument("--sim3-dialect", choices=["a", "b"], default="a", help="for Sim3 g2o output")
    conv.add_argument("--overwrite", action="store_true", help="allow the output to be the input")


def _plot(sub, groups: _Groups) -> None:
    """``plot``."""
    plot = _command(
        sub, "plot", "draw one graph or overlay several", [groups.common, groups.reading]
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
    ev.add_argument("estimate", help="g2o, TORO, TUM or KITTI")
    ev.add_argument("ground_truth", help="g2o, TORO, TUM or KITTI")
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
    ev.add_argument("--plot", metavar="FIG.png")


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
