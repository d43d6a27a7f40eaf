"""``diagnose``: the graph doctor behind ``posegraph info``.

It reports what a graph holds and every problem worth knowing before optimising it, each with
a one-line suggestion: disconnected components, missing gauge, ill-conditioned or asymmetric
information, nodes with directions that nothing measures (each on its own, or several moving
together at the file's values), duplicate edges, self-loops, breaks in the odometry chain, and
lines skipped when reading leniently.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..api import optimize
from ..graph import PoseGraph, odometry_mask
from ..io.reader import ReadResult
from ..problem.cholesky import NotPositiveDefinite
from ..problem.factors import chi2
from ..problem.observability import (
    describe_moving,
    describe_unmeasured,
    undetermined_direction,
    unmeasured_directions,
)
from ..robust.noise import NoiseClass, noise_consistency

CONDITION_LIMIT = 1e12


@dataclasses.dataclass(frozen=True)
class Problem:
    what: str
    suggestion: str


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """What ``posegraph info`` prints (and emits as JSON)."""

    path: str
    file_format: str
    group: str
    tag_counts: dict[str, int]
    nodes: int
    edges: int
    loop_closures: int
    """Edges between nodes that are not consecutive: what robust mode's "loops" class covers."""
    priors: int
    components: list[int]
    """Node count of every connected component, largest first."""
    gauge: str
    condition_numbers: dict[str, float]
    """min, median and max condition number of the information matrices that are not singular."""
    singular_information: int
    """How many information matrices are singular (λ_min ≤ 1e-12 λ_max): directions not
    measured, as by a position-only prior."""
    initial_error: float
    initial_chi2: float
    problems: list[Problem]
    lifted_scale_information: float | None
    """The log-scale information of the SE3 lines lifted to Sim3 in a file mixing both (None if
    nothing was lifted): ``ReadResult.lifted_scale_information``."""
    noise: list[NoiseClass]
    """Noise consistency per class of measurement at a least-squares solution
    (``noise.noise_consistency``); empty where no solve could be made."""

    def as_dict(self) -> dict:
        record = dataclasses.asdict(self)
        record["problems"] = [dataclasses.asdict(p) for p in self.problems]
        record["noise"] = [c.as_dict() for c in self.noise]
        return record


def diagnose(read: ReadResult) -> Diagnosis:
    """Examine a graph as read from a file."""
    graph = read.graph
    labels = graph.components() if graph.num_nodes else np.zeros(0, dtype=np.int64)
    sizes = sorted(np.bincount(labels).tolist(), reverse=True) if labels.size else []
    information = np.concatenate([graph.edges.information, graph.priors.information])
    eigenvalues = np.linalg.eigvalsh(information) if len(information) else np.zeros((0, 1))
    singular = eigenvalues[:, 0] <= 1e-12 * eigenvalues[:, -1]
    conditions, condition_problems = _conditions(information, eigenvalues[~singular])
    with np.errstate(over="ignore", invalid="ignore"):
        total = chi2(graph.values, graph.edges, graph.priors)
    noise = _noise(graph)
    problems = [
        *_component_problems(sizes),
        *_singular_problems(int(np.count_nonzero(singular[: graph.num_edges]))),
        *_observability_problems(graph),
        *condition_problems,
        *_edge_problems(graph),
        *_reading_problems(read),
        *_error_problems(total),
        *[Problem(*c.finding()) for c in noise if c.finding()],
    ]
    return Diagnosis(
        path=read.path,
        file_format=read.format,
        group=graph.group.__name__,
        tag_counts=dict(read.tag_counts),
        nodes=graph.num_nodes,
        edges=graph.num_edges,
        loop_closures=int(np.count_nonzero(~odometry_mask(graph))),
        priors=len(graph.priors),
        components=sizes,
        gauge=_gauge(graph),
        condition_numbers=conditions,
        singular_information=int(np.count_nonzero(singular)),
        initial_error=0.5 * total,
        initial_chi2=total,
        problems=problems,
        lifted_scale_information=read.lifted_scale_information,
        noise=noise,
    )


def _noise(graph: PoseGraph) -> list[NoiseClass]:
    """Noise consistency at a least-squares solution of a copy of the graph (none if the graph
    has no measurement or the solve fails: the other problems say why)."""
    if not graph.num_edges and not len(graph.priors):
        return []
    try:
        solved = optimize(graph.copy()).values
        return noise_consistency(graph, solved)
    except (ValueError, np.linalg.LinAlgError, NotPositiveDefinite):
        return []


def _component_problems(sizes: list[int]) -> list[Problem]:
    if len(sizes) <= 1:
        return []
    return [
        Problem(
            f"{len(sizes)} connected components (sizes {', '.join(map(str, sizes[:5]))}"
            f"{', …' if len(sizes) > 5 else ''})",
            "each is optimised in its own frame, its lowest id held; add edges to tie them together",
        )
    ]


def _gauge(graph: PoseGraph) -> str:
    """What holds the graph's gauge: FIX lines, priors, or each component's lowest id."""
    fixed = graph.node_ids[graph.fixed]
    if fixed.size:
        return f"fixed by FIX: nodes {', '.join(map(str, fixed[:10].tolist()))}"
    if len(graph.priors):
        return f"set by {len(graph.priors)} prior(s)"
    held = graph.node_ids[graph.gauge_nodes()][:10].tolist()
    return f"lowest id held: node {', '.join(map(str, held))}"


def _singular_problems(singular_edges: int) -> list[Problem]:
    if not singular_edges:
        return []
    return [
        Problem(
            f"{singular_edges} edge(s) have singular information: directions they do not measure",
            "fine for partial measurements, if the rest of the graph constrains those directions",
        )
    ]


def _observability_problems(graph: PoseGraph) -> list[Problem]:
    """Nodes with directions that no edge or prior measures, or that move together."""
    unmeasured = unmeasured_directions(graph)
    if unmeasured.any():
        return [
            Problem(
                f"{np.count_nonzero(unmeasured)} node(s) have directions that no edge or prior"
                f" measures ({describe_unmeasured(graph, unmeasured)})",
                "the measurements reach them there only through the residuals' curvature, so"
                " their values there are the initialisation's and their covariances mean nothing;"
                " add measurements of those directions, or fix those nodes",
            )
        ]
    if not (graph.num_nodes and graph.initialized.all()):
        return []
    moving = undetermined_direction(graph, graph.values)
    if moving is None:
        return []
    return [
        Problem(
            describe_moving(graph, moving),
            "their values along that motion are the initialisation's and their"
            " covariances are refused; add measurements that tie them to the rest in"
            " every direction, or fix one of them",
        )
    ]


def _conditions(information: np.ndarray, eigenvalues: np.ndarray) -> tuple[dict, list[Problem]]:
    """The condition numbers (min, median, max) of the information matrices that are not
    singular (their ``eigenvalues``), and the problems of ill-conditioned or asymmetric ones."""
    condition = eigenvalues[:, -1] / eigenvalues[:, 0]
    if not condition.size:
        return {}, []
    conditions = {
        "min": float(condition.min()),
        "median": float(np.median(condition)),
        "max": float(condition.max()),
    }
    problems = []
    bad = np.flatnonzero(condition > CONDITION_LIMIT)
    if bad.size:
        problems.append(
            Problem(
                f"{bad.size} information matrices have condition number above {CONDITION_LIMIT:.0e}",
                "check those edges' noise models; near-singular weights make the solve inaccurate",
            )
        )
    asymmetry = np.abs(information - np.swapaxes(information, 1, 2)).max()
    if asymmetry > 0:
        problems.append(
            Problem(
                f"information matrices are not symmetric (max |Ω − Ωᵀ| = {asymmetry:.3g})",
                "symmetrise them as (Ω + Ωᵀ)/2 before optimising",
            )
        )
    return conditions, problems


def _edge_problems(graph: PoseGraph) -> list[Problem]:
    """Duplicate edges between one pair of nodes, and breaks of the odometry chain."""
    problems = []
    i, j = graph.edges.i, graph.edges.j
    if i.size:
        pairs = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1)
        _, counts = np.unique(pairs, axis=0, return_counts=True)
        duplicates = int((counts - 1).sum())
        if duplicates:
            problems.append(
                Problem(
                    f"{duplicates} duplicate edge(s) between the same pair of nodes",
                    "fine if they are independent measurements; if copies, they count twice",
                )
            )
    chained = np.zeros(max(graph.num_nodes - 1, 0), dtype=bool)
    chained[np.minimum(i, j)[odometry_mask(graph)]] = True
    breaks = np.flatnonzero(~chained)
    if breaks.size:
        at = ", ".join(f"{graph.node_ids[k]}→{graph.node_ids[k + 1]}" for k in breaks[:5])
        problems.append(
            Problem(
                f"the odometry chain breaks {breaks.size} time(s) (at {at}{', …' if breaks.size > 5 else ''})",
                "odometry initialisation bridges breaks through other edges; check for missing odometry",
            )
        )
    return problems


def _reading_problems(read: ReadResult) -> list[Problem]:
    """Lines that lenient reading skipped, a problem per kind (``skipped_by_reason``), and nodes
    without a vertex line."""
    problems = [
        Problem(
            f"{count} line(s) skipped (first at line {line}): {why}",
            "fix those lines (an option named above may read them); otherwise they are left out",
        )
        for why, count, line in read.skipped_by_reason()
    ]
    if read.nodes_without_vertex.size:
        read_line = " that was read" if read.skipped else ""
        problems.append(
            Problem(
                f"{read.nodes_without_vertex.size} node(s) have no vertex line{read_line}",
                "the initial error above is of values composed from odometry; optimize (default --init auto) "
                "starts a graph with loops from chordal relaxation instead",
            )
        )
    return problems


def _error_problems(total: float) -> list[Problem]:
    if np.isfinite(total):
        return []
    return [
        Problem(
            f"the error at the file's values is {total} (the residuals overflow)",
            "some numbers are too large for double precision (beyond about 1e154, squares overflow)",
        )
    ]
