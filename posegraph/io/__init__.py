"""Reading and writing pose-graph files (g2o and TORO), trajectories (TUM and KITTI) and
covariances; loading a graph file ready to optimise."""

from .errors import GraphFileError
from .load import load_graph
from .options import ReadOptions
from .reader import ReadResult, read_graph
from .writer import format_g2o, format_toro, unwritable, write_graph

__all__ = [
    "GraphFileError",
    "ReadOptions",
    "ReadResult",
    "format_g2o",
    "format_toro",
    "load_graph",
    "read_graph",
    "unwritable",
    "write_graph",
]
