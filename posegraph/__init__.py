"""posegraph: pose-graph optimisation on Lie groups (SE2, SE3, Sim3)."""

from .analysis.marginals import marginals, relative_covariances
from .api import optimize
from .certification import Certificate, certify
from .graph import PoseGraph
from .graph.information import information_from_sigmas
from .io import GraphFileError, ReadOptions, load_graph, read_graph, write_graph
from .lie import SE2, SE3, SO2, SO3, Sim3
from .lie.gtsam_order import matrix_from_gtsam, matrix_to_gtsam
from .robust.spec import RobustSpec
from .sim3.scale_drift import correct_scale_drift
from .smoother import Smoother
from .solvers import Result, SolverOptions


def __getattr__(name: str) -> str:
    """``__version__``, read from the installed package's metadata on first use (importing
    ``importlib.metadata`` would slow every start of the command line)."""
    if name != "__version__":
        raise AttributeError(f"module 'posegraph' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("posegraph")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "0+unknown"


__all__ = [
    "Certificate",
    "certify",
    "SE2",
    "SE3",
    "SO2",
    "SO3",
    "GraphFileError",
    "PoseGraph",
    "ReadOptions",
    "Result",
    "RobustSpec",
    "Sim3",
    "Smoother",
    "SolverOptions",
    "correct_scale_drift",
    "information_from_sigmas",
    "load_graph",
    "marginals",
    "matrix_from_gtsam",
    "matrix_to_gtsam",
    "optimize",
    "read_graph",
    "relative_covariances",
    "write_graph",
]
