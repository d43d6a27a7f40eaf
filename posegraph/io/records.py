"""The records of a file's lines: each tag's rows checked and converted (group elements,
information matrices), priors' offsets applied, and SE3 records embedded in Sim3 in a file
that mixes both."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..graph import element_problems, information_problems, overflowing_edges
from ..graph.repair import repair_information
from ..lie import SE3
from ..sim3.lifting import lift_information, lift_se3
from .options import ReadOptions
from .parsing import LineChecker, Rows, quaternion_problems
from .tags import (
    EDGE2_ORDERS,
    G2O_TAGS,
    TORO_TAGS,
    TagFormat,
    edge2_information,
    edge2_order_text,
    prior_without_offset,
)

ALL_TAGS: dict[str, TagFormat] = {**G2O_TAGS, **TORO_TAGS}


@dataclasses.dataclass
class Collected:
    """Converted rows per kind, before the graph is assembled."""

    vertices: list = dataclasses.field(default_factory=list)  # (rows, values)
    edges: list = dataclasses.field(default_factory=list)  # (rows, measurements, information)
    priors: list = dataclasses.field(default_factory=list)
    parameters: list = dataclasses.field(default_factory=list)  # (rows, SE3 offsets)
    fixes: list = dataclasses.field(default_factory=list)  # rows
    equivalences: list = dataclasses.field(default_factory=list)  # rows
    repaired: int = 0  # information matrices changed by ``ReadOptions.repair_information``


def embed_se3_records(collected: Collected) -> None:
    """Turn SE3 vertices, edges and priors into Sim3 ones of scale 1 whose information says
    nothing of log-scale (a zero σ row and column): what an SE3 line of a file mixing SE3 and
    Sim3 states. CONVENTIONS.md: both files' vertices are world-from-node, so no inversion is
    involved. How much such a line constrains scale is the lifting step's choice
    (``sim3.lifting.lift_se3_lines``), not the reader's."""
    collected.vertices = [
        (rows, lift_se3(values) if isinstance(values, SE3) else values)
        for rows, values in collected.vertices
    ]
    for kind in ("edges", "priors"):
        setattr(
            collected,
            kind,
            [
                (rows, lift_se3(z), lift_information(info, 0.0))
                if isinstance(z, SE3)
                else (rows, z, info)
                for rows, z, info in getattr(collected, kind)
            ],
        )


def _edge2_order_advice(rows: Rows, order: str) -> str:
    """Advice for EDGE2 lines whose information is refused in ``order``: whether every one of
    them is accepted in the other order (files of both kinds exist)."""
    other = next(name for name in EDGE2_ORDERS if name != order)
    if information_problems(edge2_information(rows.numbers[:, 5:11], other))[0].any():
        return ""
    return (
        f" in the {order} order ({edge2_order_text(order)}); every EDGE2 line of this file is"
        f" positive semi-definite in the {other} order ({edge2_order_text(other)}): read it with"
        f" --edge2-order {other} (ReadOptions(edge2_order={other!r}))"
    )


def _drop(rows: Rows, measurements, information, bad: np.ndarray, message, checker: LineChecker):
    """The rows, measurements and information where ``bad`` does not hold; the rows where it
    does go to ``checker`` with ``message(k)``."""
    if not bad.any():
        return rows, measurements, information
    return checker.keep_good(rows, bad, message), measurements[~bad], information[~bad]


REPAIR_ADVICE = (
    "; --repair-information psd clips its eigenvalues, --repair-information isotropic takes"
    " SE-Sync's model of one translation and one rotation precision"
)


def _check_information(rows: Rows, measurements, information, checker: LineChecker, options):
    """The rows whose information the graph accepts, repaired first if the options say so
    (``repair_information``; ``collected.repaired`` counts the matrices changed)."""
    bad, why = information_problems(information)
    advice = ""
    if rows.tag == "EDGE2" and bad.any():
        advice = _edge2_order_advice(rows, options.edge2_order)

    def message(k: int) -> str:
        reason = why(k)
        repairable = reason.startswith("not positive semi-definite") and not advice
        return f"information matrix is {reason}{advice}{REPAIR_ADVICE if repairable else ''}"

    return _drop(rows, measurements, information, bad, message, checker)


def _repaired(spec: TagFormat, information: np.ndarray, options, collected) -> np.ndarray:
    if options.repair_information is None:
        return information
    information, changed = repair_information(information, spec.group, options.repair_information)
    collected.repaired += int(np.count_nonzero(changed))
    return information


def _check_overflow(rows: Rows, measurements, information, checker: LineChecker):
    """The edges (or priors) whose information at their start node is finite
    (``overflowing_edges``)."""
    return _drop(
        rows,
        measurements,
        information,
        overflowing_edges(measurements, information),
        lambda k: (
            f"a number is out of range: the {ALL_TAGS[rows.tag].kind}'s translation weighed by"
            f" its information overflows (Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) at node {rows.ids(0)[k]})"
        ),
        checker,
    )


def pad_missing_information(entries: list, spec: TagFormat) -> list:
    """Lines that omit their information get zeros in its place (for identity_information, which
    replaces every information after parsing)."""
    short, missing = spec.widths_without_information, spec.information_values
    return [
        (number, text + " 0" * missing if len(text.split()) in short else text)
        for number, text in entries
    ]


def _finite(rows: Rows, pieces: tuple, checker: LineChecker) -> tuple[Rows, tuple]:
    """The rows whose pieces (a group element, then information matrices) are finite, and the
    element's inverse too, and whose element the graph accepts (``element_problems``), and
    their pieces; the others are refused: a number overflowed, or underflowed (a Sim3
    log-scale of ±1e20 gives a scale of ∞ or 0, a scale of 1e120 an inverse of determinant
    1e-360, which is 0)."""
    matrices = pieces[0].as_matrix()
    finite = np.isfinite(matrices).all(axis=(1, 2))
    finite &= np.isfinite(pieces[0].inverse().as_matrix()).all(axis=(1, 2))
    for information in pieces[1:]:
        finite &= np.isfinite(information).all(axis=(1, 2))
    degenerate, why = element_problems(matrices)
    keep = finite & ~degenerate
    if keep.all():
        return rows, pieces
    rows = checker.keep_good(
        rows,
        ~keep,
        lambda k: (
            "a number is out of range: the line's pose or information overflows"
            if not finite[k]
            else f"the line's pose is not an element of {type(pieces[0]).__name__} (its "
            f"matrix has {why(k)})"
        ),
    )
    return rows, tuple(piece[keep] for piece in pieces)


def _parse(spec: TagFormat, rows: Rows, options: ReadOptions, checker: LineChecker):
    """(rows, ``spec.parse`` of them), without the rows whose numbers overflow."""
    with np.errstate(all="ignore"):  # overflow is found by _finite
        parsed = spec.parse(rows.numbers, options)
        if isinstance(parsed, tuple):
            return _finite(rows, parsed, checker)
        rows, (values,) = _finite(rows, (parsed,), checker)
    return rows, values


def convert_rows(spec: TagFormat, rows: Rows, options: ReadOptions, checker, collected):
    columns = spec.quaternion.get(rows.numbers.shape[1])
    if columns is not None:
        problems = quaternion_problems(rows.numbers[:, columns])
        bad = np.zeros(len(rows), dtype=bool)
        bad[list(problems)] = True
        rows = checker.keep_good(rows, bad, problems.__getitem__)
    if not len(rows):
        return
    if spec.kind == "vertex":
        collected.vertices.append(_parse(spec, rows, options, checker))
    elif spec.kind in ("edge", "prior"):
        if spec.kind == "edge":
            loops = rows.ids(0) == rows.ids(1)
            rows = checker.keep_good(
                rows, loops, lambda k: f"edge from node {rows.ids(0)[k]} to itself"
            )
            if not len(rows):
                return
        rows, (measurements, information) = _parse(spec, rows, options, checker)
        if options.identity_information:
            information = np.broadcast_to(np.eye(spec.group.dof), information.shape).copy()
        information = _repaired(spec, information, options, collected)
        converted = _check_information(rows, measurements, information, checker, options)
        converted = _check_overflow(*converted, checker)
        if len(converted[0]):
            (collected.edges if spec.kind == "edge" else collected.priors).append(converted)
    elif spec.kind == "parameter":
        collected.parameters.append(_parse(spec, rows, options, checker))
    elif spec.kind == "fix":
        collected.fixes.append(rows)
    else:
        collected.equivalences.append(rows)


def _offsets(collected: Collected, checker: LineChecker) -> tuple[dict[float, int], SE3]:
    """The PARAMS_SE3OFFSET lines: each parameter id's position, and the offsets."""
    position: dict[float, int] = {}
    first_line: dict[float, int] = {}
    kept = []
    for rows, offsets in collected.parameters:
        lines, keys = rows.line_numbers.tolist(), rows.numbers[:, 0].tolist()
        for k, (line, key) in enumerate(zip(lines, keys, strict=True)):
            if key in position:
                checker.fail(
                    line,
                    f"PARAMS_SE3OFFSET {key:g} is defined again (first on line {first_line[key]})",
                )
                continue
            position[key], first_line[key] = len(kept), line
            kept.append(offsets[k : k + 1])
    return position, SE3.concatenate(kept) if kept else SE3.identity((0,))


def _prior_on_node(record: tuple, position: dict[float, int], offsets: SE3, checker) -> tuple:
    """An EDGE_SE3_PRIOR record (rows, measurements, information) re-expressed on its node itself
    (``prior_without_offset``), with the offset its line names."""
    rows, measurements, information = record
    keys = rows.numbers[:, 1]
    undefined = ~np.isin(keys, list(position))
    rows = checker.keep_good(
        rows,
        undefined,
        lambda k: (
            f"offset parameter {keys[k]:g} is not defined by a PARAMS_SE3OFFSET line (for no"
            f" offset, add 'PARAMS_SE3OFFSET {keys[k]:g} 0 0 0 0 0 0 1' before it, as g2o does)"
        ),
    )
    used = offsets[np.array([position[key] for key in keys[~undefined].tolist()], dtype=int)]
    with np.errstate(all="ignore"):  # overflow is found by _finite
        moved = prior_without_offset(measurements[~undefined], information[~undefined], used)
        rows, (measurements, information) = _finite(rows, moved, checker)
    return rows, measurements, information


def apply_prior_offsets(collected: Collected, checker: LineChecker) -> None:
    """Re-express every EDGE_SE3_PRIOR on its node (g2o priors measure the node's offset pose)."""
    position, offsets = _offsets(collected, checker)
    collected.priors = [
        _prior_on_node(record, position, offsets, checker)
        if record[0].tag == "EDGE_SE3_PRIOR"
        else record
        for record in collected.priors
    ]
