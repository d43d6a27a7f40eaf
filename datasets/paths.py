"""Where the benchmark graphs are: ``../shared/datasets`` and the gtsam wheel's ``Data/``."""

from __future__ import annotations

import os
from pathlib import Path

SHARED_DATASETS_ENV = "POSEGRAPH_SHARED_DATASETS"
BENCHMARK_GRAPHS = [
    "tinyGrid3D.g2o",
    "smallGrid3D.g2o",
    "intel.g2o",
    "MIT.g2o",
    "CSAIL.g2o",
    "manhattan.g2o",
    "sphere2500.g2o",
    "parking-garage.g2o",
    "torus3D.g2o",
    "sphere_bignoise_vertex3.g2o",
]
BEST_KNOWN_ERROR = {
    "tinyGrid3D.g2o": 9.3139094,
    "smallGrid3D.g2o": 517.92533,
    "intel.g2o": 22.502117,
    "MIT.g2o": 385.11949,
    "CSAIL.g2o": 20.275442,
    "manhattan.g2o": 1774.5205,
    "sphere2500.g2o": 675.70096,
    "parking-garage.g2o": 0.6341924,
    "torus3D.g2o": 12117.637,
    "sphere_bignoise_vertex3.g2o": 1494168.8,
}
"""½ Σ rᵀΩr at the best known optimum, from ``../shared/datasets/README.md``."""


def shared_datasets_dir() -> Path | None:
    """``$POSEGRAPH_SHARED_DATASETS``, or ``../shared/datasets`` beside the project checkout."""
    candidates = []
    if os.environ.get(SHARED_DATASETS_ENV):
        candidates.append(Path(os.environ[SHARED_DATASETS_ENV]))
    project_root = Path(__file__).resolve().parent.parent  # the checkout (editable install)
    candidates += [
        project_root.parent / "shared" / "datasets",
        Path.cwd().parent / "shared" / "datasets",
    ]
    for candidate in candidates:
        if (candidate / "sphere2500.g2o").is_file():
            return candidate
    return None


def benchmark_graph(name: str) -> Path | None:
    """The benchmark graph file ``name`` (``sphere2500.g2o``) in ``shared_datasets_dir()`` or,
    fetched by ``posegraph datasets download``, in ``download.download_dir()``; None if neither
    holds it."""
    from .download import download_dir

    shared = shared_datasets_dir()
    for folder in ([shared] if shared is not None else []) + [download_dir()]:
        if (folder / name).is_file():
            return folder / name
    return None


def gtsam_data_dir() -> Path | None:
    """The ``Data/`` folder of the installed gtsam wheel, if gtsam is installed."""
    try:
        import gtsam
    except ImportError:
        return None
    folder = Path(gtsam.__file__).parent / "Data"
    return folder if folder.is_dir() else None


def benchmark_or_gtsam_graph(name: str) -> Path | None:
    """``benchmark_graph(name)``, else ``name`` in gtsam's ``Data/`` (w10000.graph, say); None
    where neither has it."""
    path = benchmark_graph(name)
    if path is None and gtsam_data_dir() is not None:
        candidate = gtsam_data_dir() / name
        path = candidate if candidate.is_file() else None
    return path
