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
from .io.trajectories import as_se3  # noqa: E402
from .lie import SE2  # noqa: E402
from .smoother import Smoother  # noqa: E402

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


def check_figure_path(path: str) -> None:
    """Raise ``ValueError`` naming ``path`` if matplotlib cannot write its suffix's format."""
    supported = FigureCanvasBase.get_supported_filetypes()
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


Drawn = PoseGraph | Smoother | ReadResult
"""What a figure draws: a graph; a smoother, with what its last robust solve rejected; or a
file read, with what its lines mark rejected (``ReadResult.rejected``)."""


def _graph(drawn: Drawn) -> PoseGraph:
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
) -> None:
    """Overlay pose graphs (label, ``Drawn``) in one figure written to ``path``; what a
    smoother's last robust solve rejected, or a file's lines mark rejected, is drawn dashed
    and circled."""
    drawn = [(label, _graph(item), _rejected(item)) for label, item in graphs]
    three_d = view == "3d" or (view == "auto" and any(g.group is not SE2 for _, g, _ in drawn))
    figure, axes = _new_axes(three_d)
    drawn_priors: list[np.ndarray] = []
    for k, (label, graph, (rejected_edges, rejected_priors)) in enumerate(drawn):
        color = COLORS[k % len(COLORS)]
        positions = as_se3(graph.values).translation
        loop = ~odometry_mask(graph)
        kept = loop & ~rejected_edges
        loops = _segments(positions, graph.edges.i[kept], graph.edges.j[kept])
        count = f"{loop.sum()} loop closures"
        if rejected_edges[loop].any():
            count += f", {np.count_nonzero(rejected_edges[loop])} rejected"
        _draw(axes, three_d, positions, loops, color, f"{label} ({count})")
        fixes = as_se3(graph.priors.measurements).translation[:, : 3 if three_d else 2]
        if len(fixes) and not any(np.array_equal(fixes, other) for other in drawn_priors):
            axes.scatter(*fixes.T, marker="x", color=color, label=f"{len(fixes)} priors")
            drawn_priors.append(fixes)
        rejected = _segments(
            positions, graph.edges.i[rejected_edges], graph.edges.j[rejected_edges]
        )
        _draw_rejected(axes, three_d, rejected, fixes[rejected_priors])
    _finish(figure, axes, three_d, title, path)


def plot_trajectories(
    trajectories: list[tuple[str, np.ndarray]],
    path: str,
    title: str | None = None,
    view: str = "auto",
) -> None:
    """Overlay trajectories given as (label, (N, 3) positions); with ``view="auto"``, 3D unless
    all are planar."""
    planar = all(np.ptp(p[:, 2]) <= 1e-9 for _, p in trajectories)
    three_d = view == "3d" or (view == "auto" and not planar)
    figure, axes = _new_axes(three_d)
    for k, (label, positions) in enumerate(trajectories):
        _draw(axes, three_d, positions, None, COLORS[k % len(COLORS)], label)
    _finish(figure, axes, three_d, title, path)
