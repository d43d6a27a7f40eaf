"""A file loaded ready to optimise or to write: read as it is (``reader.read_graph``), then the
SE3 lines of a file mixing SE3 and Sim3 lifted (``lift_se3_lines``) and the nodes that the file
gives no value composed from the others (``compose_missing_values``)."""

from __future__ import annotations

import dataclasses

from ..init.spanning_tree import compose_missing_values
from ..sim3.lifting import lift_se3_lines
from .options import ReadOptions
from .reader import ReadResult, read_graph


def load_graph(path: str, options: ReadOptions | None = None) -> ReadResult:
    """``read_graph``, with the SE3 lines of a file mixing SE3 and Sim3 given information on
    log-scale (``ReadOptions.scale_information``, or its default), and values for every node:
    those without a vertex line (a file of edges alone, or a vertex line that lenient reading
    skipped) composed along a spanning tree from the nodes that have values, or, in a file
    without vertex lines, from each component's lowest id and moved onto its priors."""
    options = ReadOptions() if options is None else options
    read = read_graph(path, options)
    if read.se3_lines is not None:
        lifted_with = lift_se3_lines(
            read.graph, read.se3_lines.edges, read.se3_lines.priors, options.scale_information
        )
        read = dataclasses.replace(read, lifted_scale_information=lifted_with)
    compose_missing_values(read.graph)
    return read
