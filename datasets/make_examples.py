"""Write the bundled example graphs from the seeded generators.

Usage: ``python -m posegraph_datasets.make_examples``. The files are committed; a test checks
that running this again reproduces them (every number to 1e-12).
"""

from __future__ import annotations

from pathlib import Path

from posegraph.io import format_g2o

from . import EXAMPLES_DIR
from .generators import manhattan_world, sphere


def example_texts() -> dict[str, str]:
    """File name → g2o text of every bundled example."""
    return {
        "manhattan_small.g2o": format_g2o(manhattan_world(num_poses=400, seed=1)[0]),
        "sphere_small.g2o": format_g2o(sphere(rings=8, poses_per_ring=20, seed=2)[0]),
    }


def main() -> None:
    for name, text in example_texts().items():
        (Path(EXAMPLES_DIR) / name).write_text(text)
        print(f"wrote {name}")


if __name__ == "__main__":
    main()
