"""The figures: eval's (trajectories coloured by error, error over distance), covariance
ellipses of 2D graphs, and the interactive HTML view, opened in headless Chromium."""

from __future__ import annotations

import contextlib
import io
import shutil
import subprocess

import numpy as np
import pytest
from posegraph_cli.main import main

from posegraph.plotting import ELLIPSE_SCALE, position_ellipse
from tests.cli.helpers import assert_not_blank

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _quiet(arguments: list) -> int:
    with contextlib.redirect_stdout(io.StringIO()):
        return main([str(a) for a in arguments])


def test_eval_plot_colours_the_estimate_by_its_error(tmp_path):
    graph, truth = tmp_path / "m.g2o", tmp_path / "truth.tum"
    assert _quiet(["generate", "manhattan", graph, "--truth", truth]) == 0
    for mode in ("xy", "xyz"):
        figure = tmp_path / f"ate_{mode}.png"
        assert _quiet(["eval", graph, truth, "--plot", figure, "--plot-mode", mode]) == 0
        assert_not_blank(figure)


def test_a_position_ellipse_turns_with_its_pose():
    """σ = 2 along the body's x and 1 along its y, for a pose facing +y: the long axis is the
    world's y, 2·√χ²₂(0.95)·2 long."""
    facing_y = np.array([[0.0, -1.0], [1.0, 0.0]])
    major, minor, angle = position_ellipse(facing_y, np.diag([4.0, 1.0]))
    assert major == pytest.approx(4 * ELLIPSE_SCALE) and minor == pytest.approx(2 * ELLIPSE_SCALE)
    assert abs(abs(angle) - 90) < 1e-9


def test_optimize_draws_the_covariance_ellipses(tmp_path):
    graph, figure = tmp_path / "m.g2o", tmp_path / "ellipses.png"
    assert _quiet(["generate", "manhattan", graph, "--poses", "150"]) == 0
    without = tmp_path / "plain.png"
    assert _quiet(["optimize", graph, "--plot", without]) == 0
    covariances = tmp_path / "covariances.txt"
    assert _quiet(["optimize", graph, "--plot", figure, "--covariances", covariances]) == 0
    assert_not_blank(figure)
    assert figure.read_bytes() != without.read_bytes()


@pytest.fixture
def html_figure(tmp_path):
    """The interactive view of a 3D graph optimised robustly, false loops rejected."""
    source, loops = tmp_path / "sphere.g2o", tmp_path / "loops.g2o"
    assert _quiet(["generate", "sphere", source, "--size", "6"]) == 0
    assert _quiet(["generate", "false-loops", loops, "--from", source, "--fraction", "0.2"]) == 0
    figure = tmp_path / "view.html"
    assert _quiet(["optimize", loops, "--robust", "gnc", "--plot", figure]) == 0
    return figure


def test_the_html_view_is_self_contained_and_shows_the_rejected_edges(html_figure):
    text = html_figure.read_text()
    assert "<script" in text and '<script src="http' not in text  # plotly.js inside
    assert "rejected" in text and "loop closures" in text


def test_the_html_view_renders_in_headless_chromium(html_figure, tmp_path):
    if CHROMIUM is None:
        pytest.skip("no Chromium (Debian package chromium; .ci/run installs it)")
    screenshot = tmp_path / "screenshot.png"
    subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--window-size=1000,800",
            "--virtual-time-budget=5000",
            f"--screenshot={screenshot}",
            html_figure.as_uri(),
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    assert_not_blank(screenshot)
    import matplotlib.image

    pixels = matplotlib.image.imread(str(screenshot))[..., :3]
    rows, columns = pixels.shape[:2]
    scene = pixels[
        rows // 4 : 3 * rows // 4, columns // 6 : columns // 2
    ]  # the graph, not the legend
    assert (scene.min(axis=2) < 0.8).mean() > 0.02


def test_only_graph_figures_have_an_html_form(tmp_path):
    """eval's and scale-drift's figures are matplotlib's: .html is refused before any work."""
    graph, truth = tmp_path / "s.g2o", tmp_path / "truth.tum"
    assert _quiet(["generate", "sphere", graph, "--size", "4", "--truth", truth]) == 0
    assert _quiet(["eval", graph, truth, "--plot", tmp_path / "ate.html"]) == 2
    assert _quiet(["scale-drift", graph, "--plot", tmp_path / "drift.html"]) == 2
    assert not list(tmp_path.glob("*.html"))
