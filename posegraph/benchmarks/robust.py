"""Robust estimation against injected false loop closures (issue table).

Usage: ``python -m posegraph.benchmarks.robust [--graphs intel manhattan sphere2500]``.
For each graph, outlier rate (false loops as a fraction of all loop closures) and seed: the
fraction of false loops rejected, the fraction of true loops wrongly rejected, and ATE
(SE3-aligned). Where a ground truth exists, the table gives ATE(robust) / ATE(outlier-free), both
against it. sphere2500's is gtsam's noise-free ``sphere2500_groundtruth.txt``. intel and
manhattan ship none, so each is run twice:
- "data": the file's measurements; the ATE is that of the robust solution against the
  outlier-free one (metres, no ratio);
- "resimulated": the file's edges and information with measurements drawn anew around its
  outlier-free solution, which is then the ground truth
  (``posegraph_datasets.generators.resimulate``, seed 0).

With ``--fixes``, the same graphs (sphere2500's own, intel and manhattan resimulated) get pose
fixes (priors) around the truth instead, a share of them false, and robust mode covers the
priors (``run_fixes``).

With ``--gtsam``, each row also runs gtsam's own GNC (``GncLMOptimizer`` with its TLS loss) on
the same graph, set up as posegraph's robust mode is (``gtsam_gnc``), side by side.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable

import numpy as np
from posegraph_datasets.generators import resimulate
from posegraph_datasets.outliers import (
    add_false_loops,
    add_fixes,
    rejection_rates,
    without_priors,
)
from posegraph_datasets.paths import gtsam_data_dir, shared_datasets_dir

from ..api import optimize
from ..graph import PoseGraph
from ..init.choice import initialize
from ..io import load_graph
from ..io.trajectories import Trajectory
from ..lie import LieGroup
from ..robust.spec import gnc_quantile, robust_mask
from ..trajectory.evaluation import evaluate
from .table import MarkdownTable


@dataclasses.dataclass(frozen=True)
class Run:
    """One robust solve of a benchmark graph."""

    values: LieGroup
    rejected_edges: np.ndarray
    rejected_priors: np.ndarray
    seconds: float


def posegraph_gnc(graph: PoseGraph, robust_priors: bool = False) -> Run:
    """``optimize(robust="gnc")`` on a copy of ``graph``, timed with its initialisation."""
    work = graph.copy()
    start = time.perf_counter()
    result = optimize(work, robust="gnc", robust_priors=robust_priors)
    seconds = time.perf_counter() - start
    summary = result.summary
    return Run(result.values, summary.rejected_edges, summary.rejected_priors, seconds)


def gtsam_gnc(graph: PoseGraph, robust_priors: bool = False) -> Run:
    """gtsam's GNC with its TLS loss set up as posegraph's robust mode is: from the odometry
    chain, with the loop closures (and the priors, with ``robust_priors``) under the kernel of
    the same quantile (``robust.spec.gnc_quantile``; ``posegraph.validation.gtsam_bridge.gnc_tls``)."""
    from ..validation.gtsam_bridge import gnc_tls

    start = initialize(graph, "odometry")
    loops = robust_mask(graph, "loops")
    measured = int(loops.sum()) + (len(graph.priors) if robust_priors else 0)
    return Run(*gnc_tls(graph, start, loops, robust_priors, gnc_quantile(measured)))


def ground_truth(name: str) -> PoseGraph | None:
    """Ground-truth poses where they ship (sphere2500), else None."""
    folder = gtsam_data_dir()
    if name == "sphere2500" and folder is not None:
        return load_graph(str(folder / "sphere2500_groundtruth.txt")).graph
    return None


def with_truth(name: str, graph: PoseGraph) -> tuple[str, PoseGraph, LieGroup]:
    """(measurements, graph, true poses in its node order): sphere2500's own measurements and
    gtsam's ground truth, or the graph resimulated around its outlier-free solution, which is
    then the truth."""
    truth = ground_truth(name)
    if truth is not None:
        return "data", graph, truth.values_of(graph.node_ids)
    solution = optimize(graph.copy()).values
    return "resimulated", resimulate(graph, solution, seed=0), solution


def cases(name: str) -> list[tuple[str, PoseGraph, Trajectory | None]]:
    """(measurements, graph, ground truth or None) for the benchmark graph ``name``."""
    graph = load_graph(str(shared_datasets_dir() / f"{name}.g2o")).graph
    label, measured, truth = with_truth(name, graph)
    own = [] if measured is graph else [("data", graph, None)]
    return own + [(label, measured, Trajectory.of_graph(measured, truth))]


def _solvers(gtsam: bool) -> list[Callable[..., Run]]:
    """posegraph's robust mode, then with ``gtsam`` gtsam's GNC."""
    return [posegraph_gnc, gtsam_gnc] if gtsam else [posegraph_gnc]


def _header(shared: str, scored: str, gtsam: bool) -> str:
    """The columns shared by a row's solves, then each solve's (gtsam's prefixed), then with
    ``gtsam`` posegraph's time over gtsam's."""
    if not gtsam:
        return f"{shared} | {scored}"
    prefixed = " | ".join(f"gtsam {column}" for column in scored.split(" | "))
    return f"{shared} | {scored} | {prefixed} | time ratio"


def _time_ratio(runs: list[Run]) -> list[str]:
    return [f"{runs[0].seconds / runs[1].seconds:.2f}"] if len(runs) == 2 else []


def _loop_scores(
    graph: PoseGraph, false: np.ndarray, run: Run, reference: Trajectory, ate_clean: float | None
) -> str:
    """false rejected | true wrongly rejected | ATE | ATE ratio (– without a truth) | time."""
    false_rejected, true_rejected = rejection_rates(graph, false, run.rejected_edges)
    ate = evaluate(Trajectory.of_graph(graph, run.values), reference).ate.rmse
    ratio = "–" if ate_clean is None else f"{ate / ate_clean:.3f}"
    return f"{false_rejected:.1%} | {true_rejected:.2%} | {ate:.4g} | {ratio} | {run.seconds:.1f}"


def run(names: list[str], fractions: list[float], seeds: list[int], gtsam: bool = False) -> str:
    """The false-loop table; with ``gtsam``, gtsam's GNC on each graph too."""
    table = MarkdownTable(
        _header(
            "graph | measurements | false loops | seed | ATE outlier-free | ATE vs",
            "false rejected | true wrongly rejected | ATE robust | ratio | time (s)",
            gtsam,
        ),
        echo=True,
    )
    for name in names:
        for label, graph, truth in cases(name):
            clean = Trajectory.of_graph(graph, optimize(graph.copy()).values)
            ate_clean = evaluate(clean, truth).ate.rmse if truth else None
            against = "ground truth" if truth else "outlier-free"
            for fraction in fractions:
                for seed in seeds:
                    corrupted, false = add_false_loops(graph, fraction, seed)
                    runs = [solver(corrupted) for solver in _solvers(gtsam)]
                    cells = [
                        f"{name} | {label} | {fraction:.0%} | {seed} "
                        f"| {ate_clean or 0.0:.4g} | {against}"
                    ]
                    cells += [
                        _loop_scores(corrupted, false, r, truth or clean, ate_clean) for r in runs
                    ]
                    table.add(" | ".join(cells + _time_ratio(runs)))
    return str(table)


def _fix_scores(
    graph: PoseGraph, false: np.ndarray, run: Run, reference: Trajectory, ate_clean: float
) -> str:
    """false rejected | true wrongly rejected | loops rejected | ATE | ATE ratio | time."""
    rejected = np.zeros(false.size, dtype=bool)
    rejected[run.rejected_priors] = True
    ate = evaluate(Trajectory.of_graph(graph, run.values), reference).ate.rmse
    return (
        f"{rejected[false].mean():.1%} | {rejected[~false].mean():.2%} "
        f"| {len(run.rejected_edges)} | {ate:.4g} | {ate / ate_clean:.3f} | {run.seconds:.1f}"
    )


def run_fixes(
    names: list[str], fractions: list[float], seeds: list[int], gtsam: bool = False
) -> str:
    """Pose fixes (σ 0.5 m and 0.05 rad) on every 10th node around the true poses, a share of
    them false, with ``robust="gnc", robust_priors=True``: the share of false fixes rejected,
    of true ones wrongly rejected, and the ATE against the truth relative to the solution
    without the false fixes; with ``gtsam``, gtsam's GNC on each graph too."""
    table = MarkdownTable(
        _header(
            "graph | false fixes | seed | ATE without them",
            "false rejected | true wrongly rejected | loops rejected | ATE robust | ratio "
            "| time (s)",
            gtsam,
        ),
        echo=True,
    )
    for name in names:
        graph = load_graph(str(shared_datasets_dir() / f"{name}.g2o")).graph
        _, measured, truth = with_truth(name, graph)
        d, dof = graph.group.point_dim, graph.group.dof
        information = np.diag([4.0] * d + [400.0] * (dof - d))
        reference = Trajectory.of_graph(measured, truth)
        for fraction in fractions:
            for seed in seeds:
                fixed, false = add_fixes(measured, truth, 10, information, fraction, seed)
                clean = without_priors(fixed, false)
                ate_clean = evaluate(Trajectory.of_graph(clean, optimize(clean).values), reference)
                runs = [solver(fixed, robust_priors=True) for solver in _solvers(gtsam)]
                cells = [f"{name} | {fraction:.0%} | {seed} | {ate_clean.ate.rmse:.4g}"]
                cells += [_fix_scores(fixed, false, r, reference, ate_clean.ate.rmse) for r in runs]
                table.add(" | ".join(cells + _time_ratio(runs)))
    return str(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="*", default=["intel", "manhattan", "sphere2500"])
    parser.add_argument("--fractions", nargs="*", type=float, default=[0.1, 0.3])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument(
        "--fixes", action="store_true", help="false pose fixes (priors) instead of false loops"
    )
    parser.add_argument(
        "--gtsam",
        action="store_true",
        help="also run gtsam's GNC (TLS) on each graph, side by side",
    )
    args = parser.parse_args()
    if shared_datasets_dir() is None:
        raise SystemExit("../shared/datasets is not beside this checkout")
    (run_fixes if args.fixes else run)(args.graphs, args.fractions, args.seeds, args.gtsam)


if __name__ == "__main__":
    main()
