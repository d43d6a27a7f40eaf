"""posegraph: pose-graph optimisation on Lie groups (SE2, SE3, Sim3)."""

from importlib.metadata import PackageNotFoundError, version

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

try:
    __version__ = version("posegraph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

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
