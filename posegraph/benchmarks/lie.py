"""Batched Lie-group throughput against gtsam (one call per element) and scipy's Rotation.

Usage: ``python -m posegraph.benchmarks.lie [--count 100000]``. Prints a markdown table of the
time for ``count`` elements and the speed-up of posegraph's batched call over each peer.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..lie import SE3, Sim3
from .table import MarkdownTable
from .timing import at_least, best_time


def _peers(count: int, rng: np.random.Generator):
    """(operation, posegraph call, gtsam loop or None, scipy call or None)."""
    import gtsam
    from scipy.spatial.transform import Rotation

    se3_tangents = rng.uniform(-1, 1, (count, 6))
    sim3_tangents = rng.uniform(-1, 1, (count, 7))
    x, y = SE3.exp(se3_tangents), SE3.exp(se3_tangents[::-1])
    s = Sim3.exp(sim3_tangents)
    gtsam_tangents = np.concatenate([se3_tangents[:, 3:], se3_tangents[:, :3]], axis=1)
    gx = [gtsam.Pose3.Expmap(v) for v in gtsam_tangents]
    gy = gx[::-1]
    sim3_gtsam_tangents = sim3_tangents[:, [3, 4, 5, 0, 1, 2, 6]]
    gs = [gtsam.Similarity3.Expmap(v) for v in sim3_gtsam_tangents]
    rx, ry = Rotation.from_matrix(x.rotation), Rotation.from_matrix(y.rotation)
    rotvecs = se3_tangents[:, 3:]
    return [
        (
            "SE3 exp",
            lambda: SE3.exp(se3_tangents),
            lambda: [gtsam.Pose3.Expmap(v) for v in gtsam_tangents],
            lambda: Rotation.from_rotvec(rotvecs).as_matrix(),
        ),
        ("SE3 log", x.log, lambda: [gtsam.Pose3.Logmap(p) for p in gx], rx.as_rotvec),
        (
            "SE3 exp + log",
            lambda: SE3.exp(se3_tangents).log(),
            lambda: [gtsam.Pose3.Logmap(gtsam.Pose3.Expmap(v)) for v in gtsam_tangents],
            lambda: Rotation.from_rotvec(rotvecs).as_rotvec(),
        ),
        (
            "SE3 compose",
            lambda: x @ y,
            lambda: [a.compose(b) for a, b in zip(gx, gy, strict=True)],
            lambda: rx * ry,
        ),
        (
            "SE3 jr_inv",
            lambda: SE3.jr_inv(se3_tangents),
            lambda: [gtsam.Pose3.LogmapDerivative(v) for v in gtsam_tangents],
            None,
        ),
        (
            "Sim3 exp",
            lambda: Sim3.exp(sim3_tangents),
            lambda: [gtsam.Similarity3.Expmap(v) for v in sim3_gtsam_tangents],
            None,
        ),
        ("Sim3 log", s.log, lambda: [gtsam.Similarity3.Logmap(p) for p in gs], None),
    ]


def run(count: int) -> str:
    """Time every operation and return the markdown table."""
    rng = np.random.default_rng(0)
    table = MarkdownTable(
        "operation | posegraph (ms) | gtsam loop (ms) | speed-up | scipy Rotation (ms)"
    )
    for name, ours, gtsam_loop, scipy_call in _peers(count, rng):
        t_ours = best_time(ours)
        t_gtsam = best_time(gtsam_loop, repeats=1)
        t_scipy = f"{1e3 * best_time(scipy_call):.1f}" if scipy_call else "–"
        ratio = t_gtsam / t_ours
        table.add(f"{name} | {1e3 * t_ours:.1f} | {1e3 * t_gtsam:.1f} | {ratio:.1f}× | {t_scipy}")
    caption = f"Batched throughput on {count} elements (best of 3; scipy: the rotation part only)."
    return f"{caption}\n\n{table}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=at_least(1), default=100_000)
    print(run(parser.parse_args().count))


if __name__ == "__main__":
    main()
