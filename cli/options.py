"""The option groups that several subcommands share (argparse parents): output form, reading,
solving, and the output file's format."""

from __future__ import annotations

import argparse

from posegraph.benchmarks.timing import at_least
from posegraph.init.choice import INITIALIZERS
from posegraph.io.conversion import GRAPH_FORMATS, TRAJECTORY_FORMATS
from posegraph.io.tags import EDGE2_ORDERS
from posegraph.solvers.options import METHODS


def common() -> argparse.ArgumentParser:
    """Options of every command: the output's form."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--json", action="store_true", help="print one JSON document (README: schema)"
    )
    common.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    common.add_argument("--debug", action="store_true", help="show tracebacks")
    return common


def reading() -> argparse.ArgumentParser:
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


def solving() -> argparse.ArgumentParser:
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


def output_format(command: argparse.ArgumentParser) -> None:
    """``--to``: the format of the output file."""
    command.add_argument(
        "--to",
        choices=[*GRAPH_FORMATS, *TRAJECTORY_FORMATS],
        help="the output's format (default: by its suffix: .g2o, .graph, .tum, .kitti)",
    )
