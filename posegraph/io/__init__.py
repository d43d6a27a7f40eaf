"""Reading and writing pose-graph files (g2o and TORO)."""

from .errors import GraphFileError
from .options import ReadOptions
from .reader import ReadResult, read_graph
from .writer import format_g2o, format_toro, unwritable, write_graph

__all__ = [
    "GraphFileError",
    "ReadOptions",
    "ReadResult",
    "format_g2o",
    "format_toro",
    "read_graph",
    "unwritable",
    "write_graph",
]
