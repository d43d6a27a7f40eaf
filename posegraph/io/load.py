"""A file loaded ready to optimise or to write: read as it is (``reader.read_graph``), then the
nodes that the file gives no value composed from the others (``compose_missing_values``)."""

from __future__ import annotations

from ..init.spanning_tree import compose_missing_values
from .options import ReadOptions
from .reader import ReadResult, read_graph


def load_graph(path: str, options: ReadOptions | None = None) -> ReadResult:
    """``read_graph``, with values for every node: those without a vertex line (a file of edges
    alone, or a vertex line that lenient reading skipped) composed along a spanning tree from
    the nodes that have values, or, in a file without vertex lines, from each component's
    lowest id and moved onto its priors."""
    read = read_graph(path, options)
    compose_missing_values(read.graph)
    return read
