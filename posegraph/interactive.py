"""Interactive HTML figures of pose graphs (plotly): one self-contained file that turns, zooms
and pans in any browser. Odometry is the trajectory line, loop closures thin lines, rejected
measurements red and dashed, priors crosses; each layer toggles from the legend."""

from __future__ import annotations

import numpy as np

from .graph import PoseGraph, odometry_mask
from .io.atomic import atomic_path
from .io.trajectories import as_se3


def _segments(positions: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Segments i → j as one polyline broken by NaN rows (plotly draws no line across them)."""
    lines = np.full((3 * len(i), 3), np.nan)
    lines[0::3], lines[1::3] = positions[i], positions[j]
    return lines


def write_html(
    graphs: list[tuple[str, PoseGraph, tuple[np.ndarray, np.ndarray]]],
    path: str,
    title: str | None,
    colors: list[str],
    rejected_color: str,
) -> None:
    """Write the 3D figure of (label, graph, (rejected edge mask, rejected prior mask)) to
    ``path`` as one HTML file that holds plotly.js (no network needed to view it): graph k in
    ``colors[k]`` (cycled), what was rejected in ``rejected_color``."""
    import plotly.graph_objects as go

    figure = go.Figure()
    for k, (label, graph, rejected) in enumerate(graphs):
        color = colors[k % len(colors)]
        for trace in _traces(label, graph, rejected, color, rejected_color):
            figure.add_trace(trace)
    figure.update_layout(
        title=title,
        scene=dict(aspectmode="data", xaxis_title="x", yaxis_title="y", zaxis_title="z"),
        margin=dict(l=0, r=0, t=40 if title else 0, b=0),
        legend=dict(itemsizing="constant"),
    )
    with atomic_path(path) as temporary:
        figure.write_html(str(temporary), include_plotlyjs=True, full_html=True)


def _traces(
    label: str,
    graph: PoseGraph,
    rejected: tuple[np.ndarray, np.ndarray],
    color: str,
    rejected_color: str,
):
    """One graph's layers: its trajectory, its kept and rejected loop closures, its priors."""
    import plotly.graph_objects as go

    rejected_edges, rejected_priors = rejected
    positions = as_se3(graph.values).translation
    loop = ~odometry_mask(graph)
    kept = loop & ~rejected_edges
    edges = graph.edges
    layers = [
        (label, positions, dict(color=color, width=3)),
        (
            f"{label}: {np.count_nonzero(kept)} loop closures",
            _segments(positions, edges.i[kept], edges.j[kept]),
            dict(color=color, width=1),
        ),
        (
            f"{label}: {np.count_nonzero(rejected_edges)} rejected",
            _segments(positions, edges.i[rejected_edges], edges.j[rejected_edges]),
            dict(color=rejected_color, width=2, dash="dash"),
        ),
    ]
    for name, points, line in layers:
        if len(points):
            x, y, z = points.T
            yield go.Scatter3d(x=x, y=y, z=z, mode="lines", name=name, line=line)
    fixes = as_se3(graph.priors.measurements).translation
    if len(fixes):
        x, y, z = fixes.T
        colors = np.where(rejected_priors, rejected_color, color)
        name = f"{label}: {len(fixes)} priors ({np.count_nonzero(rejected_priors)} rejected)"
        marker = dict(symbol="x", size=3, color=colors)
        yield go.Scatter3d(x=x, y=y, z=z, mode="markers", name=name, marker=marker)
