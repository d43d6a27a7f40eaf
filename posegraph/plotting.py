"""Figures of pose graphs and trajectories (matplotlib's Agg backend: works headless).

Odometry (edges between consecutive nodes) is drawn as the trajectory line; loop closures as
thin lines of a lighter shade; priors (GNSS fixes, say) as crosses at their measured positions.
Several inputs are overlaid, one colour each (before/after); priors shared with an earlier input
are drawn once. In a smoother's graph, the measurements its last robust solve rejected
(``Smoother.rejected``) are drawn apart: edges dashed in red, priors circled in red.
SE2 graphs are drawn top-down; SE3 and Sim3 in 3D (or top-down with ``view="top"``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.backend_bases import FigureCanvasBase  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection  # noqa: E402

from .graph import (
    PoseGraph,  # noqa: E402
    odometry_mask,  # noqa: E402
)
from .io.atomic import atomic_path  # noqa: E402
from .io.reader import ReadResult  # noqa: E402
from .io.trajectories import Trajectory, as_se3  # noqa: E402
from .lie import SE2, SE3  # noqa: E402
from .smoother import Smoother  # noqa: E402
from .trajectory.evaluation import Evaluation  # noqa: E402

COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:olive"]
REJECTED_COLOR = "tab:red"


def _segments(positions: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    return np.stack([positions[i], positions[j]], axis=1)


def _new_axes(three_d: bool):
    figure = plt.figure(figsize=(8, 7), dpi=110)
    axes = figure.add_subplot(projection="3d") if three_d else figure.add_subplot()
    return figure, axes


def _add_lines(axes, three_d: bool, segments: np.ndarray, **style) -> None:
    """Segments (k, 2, 3) as one collection, in 3D or top-down."""
    dims = 3 if three_d else 2
    collection_class = Line3DCollection if three_d else LineCollection
    axes.add_collection(collection_class(segments[:, :, :dims], **style))


def _draw(axes, three_d: bool, positions, loops, color, label) -> None:
    if loops is not None and len(loops):
        _add_lines(axes, three_d, loops, colors=color, linewidths=0.4, alpha=0.35)
    axes.plot(*positions[:, : 3 if three_d else 2].T, color=color, linewidth=1.0, label=label)


def _draw_rejected(axes, three_d: bool, segments: np.ndarray, fixes: np.ndarray) -> None:
    """The edges (``segments``) and the priors' positions (``fixes``, in the figure's dimensions)
    that a robust run rejected."""
    if len(segments):
        _add_lines(
            axes,
            three_d,
            segments,
            colors=REJECTED_COLOR,
            linewidths=0.6,
            linestyles="dashed",
            label=f"{len(segments)} rejected edges",
        )
    if len(fixes):
        axes.scatter(
            *fixes.T,
            marker="o",
            s=60,
            facecolors="none",
            edgecolors=REJECTED_COLOR,
            label=f"{len(fixes)} rejected priors",
        )


def _finish(figure, axes, three_d: bool, title: str | None, path: str) -> None:
    if three_d:
        axes.set_xlabel("x")
        axes.set_ylabel("y")
        axes.set_zlabel("z")
        low, high = axes.get_w_lims()[::2], axes.get_w_lims()[1::2]
        span = max(h - lo for lo, h in zip(low, high, strict=True)) / 2
        centre = [(lo + h) / 2 for lo, h in zip(low, high, strict=True)]
        axes.set_xlim(centre[0] - span, centre[0] + span)
        axes.set_ylim(centre[1] - span, centre[1] + span)
        axes.set_zlim(centre[2] - span, centre[2] + span)
    else:
        axes.set_aspect("equal", adjustable="datalim")
        axes.set_xlabel("x")
        axes.set_ylabel("y")
        axes.autoscale_view()
    if title:
        axes.set_title(title)
    axes.legend(loc="best", fontsize="small")
    save_figure(figure, path)


def check_figure_path(path: str, interactive: bool = False) -> None:
    """Raise ``ValueError`` naming ``path`` if matplotlib cannot write its suffix's format (nor,
    where the figure has an ``interactive`` form, ``plot_graphs``', is it ``.html``)."""
    supported = dict(FigureCanvasBase.get_supported_filetypes())
    if interactive:
        supported["html"] = "interactive (plotly)"
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in supported:
        raise ValueError(
            f"{path}: cannot draw a figure as {suffix or 'no suffix'!r} "
            f"(known: {', '.join(sorted(supported))})"
        )


def save_figure(figure, path: str) -> None:
    """Save atomically (``atomic_path``) and close."""
    check_figure_path(path)
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, bbox_inches="tight")
    finally:
        plt.close(figure)


Drawn = PoseGraph | Smoother | ReadResult | Trajectory
"""What a figure draws: a graph; a smoother, with what its last robust solve rejected; a file
read, with what its lines mark rejected (``ReadResult.rejected``); or a trajectory."""


def _graph(drawn: Drawn) -> PoseGraph:
    """The graph drawn; a trajectory is drawn as the graph of its poses alone."""
    if isinstance(drawn, Trajectory):
        graph = PoseGraph(SE3)
        graph.add_nodes(np.arange(len(drawn.keys)), drawn.poses)
        return graph
    return drawn if isinstance(drawn, PoseGraph) else drawn.graph


def _rejected(drawn: Drawn) -> tuple[np.ndarray, np.ndarray]:
    """Masks over the edges and priors of what was rejected (none for a graph alone)."""
    if isinstance(drawn, Smoother):
        return drawn.rejected()
    if isinstance(drawn, ReadResult) and drawn.rejected is not None:
        return drawn.rejected
    graph = _graph(drawn)
    return np.zeros(graph.num_edges, dtype=bool), np.zeros(len(graph.priors), dtype=bool)


def plot_graphs(
    graphs: list[tuple[str, Drawn]],
    path: str,
    title: str | None = None,
    view: str = "auto",
    covariances: np.ndarray | None = None,
) -> None:
    """Overlay pose graphs (label, ``Drawn``) in one figure written to ``path``; what a
    smoother's last robust solve rejected, or a file's lines mark rejected, is drawn dashed
    and circled. Drawn top-down, the last graph's poses get the ellipses of their marginal
    ``covariances`` (one (d, d) matrix per node, over the tangent) where given."""
    drawn = [(label, _graph(item), _rejected(item)) for label, item in graphs]
    if Path(path).suffix.lower() == ".html":
        from matplotlib.colors import to_hex

        from .interactive import write_html

        colors = [to_hex(color) for color in COLORS]  # plotly takes hex, not matplotlib's names
        write_html(drawn, path, title, colors, to_hex(REJECTED_COLOR))
        return
    three_d = view == "3d" or (view == "auto" and not all(_planar(g) for _, g, _ in drawn))
    figure, axes = _new_axes(three_d)
    drawn_priors: list[np.ndarray] = []
    for k, (label, graph, (rejected_edges, rejected_priors)) in enumerate(drawn):
        color = COLORS[k % len(COLORS)]
        positions = as_se3(graph.values).translation
        loop = ~odometry_mask(graph)
        kept = loop & ~rejected_edges
        loops = _segments(positions, graph.edges.i[kept], graph.edges.j[kept])
        count = f" ({loop.sum()} loop closures" if graph.num_edges else ""
        if rejected_edges[loop].any():
            count += f", {np.count_nonzero(rejected_edges[loop])} rejected"
        _draw(axes, three_d, positions, loops, color, f"{label}{count}{')' if count else ''}")
        fixes = as_se3(graph.priors.measurements).translation[:, : 3 if three_d else 2]
        if len(fixes) and not any(np.array_equal(fixes, other) for other in drawn_priors):
            axes.scatter(*fixes.T, marker="x", color=color, label=f"{len(fixes)} priors")
            drawn_priors.append(fixes)
        rejected = _segments(
            positions, graph.edges.i[rejected_edges], graph.edges.j[rejected_edges]
        )
        _draw_rejected(axes, three_d, rejected, fixes[rejected_priors])
    if covariances is not None and not three_d:
        _draw_ellipses(axes, drawn[-1][1], covariances, COLORS[(len(drawn) - 1) % len(COLORS)])
    _finish(figure, axes, three_d, title, path)


ELLIPSE_SCALE = float(np.sqrt(5.991))
"""Half-axes of a position ellipse in standard deviations: √χ²₂(0.95), the 95% region."""

MAX_ELLIPSES = 150
"""At most this many ellipses, at evenly spaced poses, so that they stay readable."""


def position_ellipse(rotation: np.ndarray, covariance: np.ndarray) -> tuple[float, float, float]:
    """The 95% ellipse of a planar position: (major axis, minor axis, the major axis' angle in
    degrees from x), for a pose of 2 × 2 ``rotation`` whose (2, 2) ``covariance`` is over the
    translation part ρ of the tangent of X·Exp(δ); the position moves by R·ρ, so its world-frame
    covariance is R Σ_ρρ Rᵀ."""
    variances, directions = np.linalg.eigh(rotation @ covariance @ rotation.T)
    minor, major = 2 * ELLIPSE_SCALE * np.sqrt(np.clip(variances, 0, None))
    angle = float(np.degrees(np.arctan2(directions[1, 1], directions[0, 1])))
    return float(major), float(minor), angle


def _draw_ellipses(axes, graph: PoseGraph, covariances: np.ndarray, color: str) -> None:
    """The 95% ellipses of the horizontal positions of (at most ``MAX_ELLIPSES``) poses."""
    from matplotlib.patches import Ellipse

    poses = as_se3(graph.values)
    every = max(1, graph.num_nodes // MAX_ELLIPSES)
    label = "95% position ellipses"
    for k in range(0, graph.num_nodes, every):
        major, minor, angle = position_ellipse(poses.rotation[k, :2, :2], covariances[k, :2, :2])
        if major <= 0:
            continue  # a held node
        axes.add_patch(
            Ellipse(
                poses.translation[k, :2],
                major,
                minor,
                angle=angle,
                fill=False,
                edgecolor=color,
                linewidth=0.6,
                alpha=0.8,
                label=label,
            )
        )
        label = None


def _planar(graph: PoseGraph) -> bool:
    """Whether a graph is drawn flat: SE2, or poses that keep to one height."""
    return graph.group is SE2 or _flat(as_se3(graph.values).translation)


def _flat(positions: np.ndarray) -> bool:
    """Whether (N, 3) positions keep to one height."""
    return bool(np.ptp(positions[:, 2]) <= 1e-9)


def plot_trajectories(
    trajectories: list[tuple[str, np.ndarray]],
    path: str,
    title: str | None = None,
    view: str = "auto",
) -> None:
    """Overlay trajectories given as (label, (N, 3) positions); with ``view="auto"``, 3D unless
    all are planar."""
    planar = all(_flat(p) for _, p in trajectories)
    three_d = view == "3d" or (view == "auto" and not planar)
    figure, axes = _new_axes(three_d)
    for k, (label, positions) in enumerate(trajectories):
        _draw(axes, three_d, positions, None, COLORS[k % len(COLORS)], label)
    _finish(figure, axes, three_d, title, path)


PLOT_MODES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2), "xyz": (0, 1, 2)}
"""The axes a trajectory is drawn on, as evo's ``--plot_mode``."""


def plot_evaluation(
    evaluation: Evaluation,
    truth: np.ndarray,
    path: str,
    mode: str = "xy",
    colormap_max: float | None = None,
    title: str | None = None,
) -> None:
    """The figure of ``posegraph eval`` (as evo's ``evo_ape --plot``): the whole ground truth
    (``truth``, (N, 3) positions) dashed in grey and the aligned estimate coloured by each
    pose's ATE, from 0 to ``colormap_max`` (default the largest), on the axes of ``mode``;
    beside it, the ATE against the distance travelled along the ground truth, with its RMSE,
    mean and median."""
    axes_of = PLOT_MODES[mode]
    three_d = len(axes_of) == 3
    figure = plt.figure(figsize=(13, 5.5), dpi=110)
    trajectory = figure.add_subplot(1, 2, 1, projection="3d" if three_d else None)
    errors = evaluation.ate_errors
    estimate = evaluation.aligned_estimate.translation[:, axes_of]
    trajectory.plot(*truth[:, axes_of].T, "--", color="0.45", linewidth=1.0, label="ground truth")
    segments = np.stack([estimate[:-1], estimate[1:]], axis=1)
    norm = plt.Normalize(0.0, colormap_max or max(float(errors.max()), 1e-12))
    colors = (Line3DCollection if three_d else LineCollection)(
        segments, cmap="jet", norm=norm, linewidths=1.6, label="estimate"
    )
    colors.set_array((errors[:-1] + errors[1:]) / 2)
    trajectory.add_collection(colors)
    figure.colorbar(colors, ax=trajectory, label="ATE", shrink=0.8)
    names = "xyz"
    trajectory.set_xlabel(names[axes_of[0]])
    trajectory.set_ylabel(names[axes_of[1]])
    if three_d:
        trajectory.set_zlabel("z")
        trajectory.auto_scale_xyz(*estimate.T)
    else:
        trajectory.set_aspect("equal", adjustable="datalim")
        trajectory.autoscale_view()
    trajectory.legend(loc="best", fontsize="small")
    trajectory.set_title(f"{evaluation.alignment}-aligned estimate, coloured by ATE")

    over_distance = figure.add_subplot(1, 2, 2)
    over_distance.plot(evaluation.distance_travelled, errors, color="tab:blue", linewidth=1.0)
    statistics = evaluation.ate
    for value, name, style in (
        (statistics.rmse, "rmse", "-"),
        (statistics.mean, "mean", "--"),
        (statistics.median, "median", ":"),
    ):
        over_distance.axhline(
            value, linestyle=style, color="0.3", linewidth=0.9, label=f"{name} {value:.4g}"
        )
    over_distance.set_xlabel("distance travelled along the ground truth")
    over_distance.set_ylabel("ATE")
    over_distance.set_ylim(bottom=0)
    over_distance.legend(loc="best", fontsize="small")
    over_distance.set_title("ATE over distance")
    if title:
        figure.suptitle(title)
    save_figure(figure, path)
