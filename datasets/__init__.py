"""Bundled example graphs, their generators, and the locations of benchmark data.

Installed as package ``posegraph_datasets``. The ``.g2o`` files here are written by
``python -m posegraph_datasets.make_examples`` from the seeded generators; tests check that
regenerating them reproduces them (every number to 1e-12).
"""

from pathlib import Path

EXAMPLES_DIR = Path(__file__).resolve().parent


def example(name: str) -> Path:
    """Path of a bundled example, e.g. ``example("manhattan_small.g2o")``."""
    path = EXAMPLES_DIR / name
    if not path.is_file():
        available = ", ".join(sorted(p.name for p in EXAMPLES_DIR.glob("*.g2o")))
        raise FileNotFoundError(f"no bundled example {name!r}; available: {available}")
    return path
