"""``PoseGraph``: nodes on one Lie group, between edges, priors, and fixed nodes.

Node ids are arbitrary integers; internally every array refers to nodes by their *index*, the
order in which they were added. Edges are stored stacked: index arrays ``i``, ``j``, stacked
measurements and (…, d, d) information matrices over the tangent of CONVENTIONS.md.
A between edge i → j measures Z ≈ Xᵢ⁻¹ Xⱼ; a prior on i measures Z ≈ Xᵢ.

The graph grows in place (``add_nodes``, ``add_edges``, ``add_priors``, ``fix``), shrinks
(``remove_edges``, ``remove_priors``, ``remove_nodes``) and keeps its values, so a back end can
edit it and optimise again from the last solution.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from .lie import SE2, SE3, LieGroup, Sim3

if TYPE_CHECKING:
    from .solvers import Summary

POSE_GROUPS: tuple[type[LieGroup], ...] = (SE2, SE3, Sim3)


def node_id_array(node_ids: Iterable[int] | np.ndarray | int) -> np.ndarray:
    """Node ids as a 1-D int64 array. Whole floats (ids loaded with ``numpy.loadtxt``) are
    taken; anything else that is not an integer of at most 64 bits, or ids nested in more than
    one dimension, is refused with a ``ValueError`` naming the first offending id."""
    given = np.atleast_1d(np.asarray(node_ids))
    if given.ndim != 1:
        raise ValueError(f"node ids are one sequence of integers, not of shape {given.shape}")
    kind = given.dtype.kind
    if kind == "i":
        whole = np.ones(given.shape, dtype=bool)
    elif kind == "u":
        whole = given < 2**63
    elif kind == "f":
        whole = (given == np.trunc(given)) & (-(2.0**63) <= given) & (given < 2.0**63)
    else:
        whole = np.array([type(k) is int and -(2**63) <= k < 2**63 for k in given.tolist()])
    if not whole.all():
        first = given[~whole].tolist()[0]
        raise ValueError(f"node id {first!r} is not an integer of at most 64 bits")
    return given.astype(np.int64)


def named_nodes(node_ids: np.ndarray, shown: int = 3) -> str:
    """Node ids as a phrase: "node 4", or "nodes 4, 6, 8, … (20 nodes)" past ``shown``."""
    named = ", ".join(str(node) for node in node_ids[:shown])
    if len(node_ids) == 1:
        return f"node {named}"
    return f"nodes {named}" + (f", … ({len(node_ids)} nodes)" if len(node_ids) > shown else "")


def element_problems(matrices: np.ndarray) -> tuple[np.ndarray, Callable[[int], str]]:
    """Which of (n, m, m) matrices cannot be group elements, and what the k-th has: a last
    entry other than 1 (by more than 1e-4), or a linear block of determinant ≤ 0 (or NaN, for
    a matrix that is not finite, which callers refuse first). A Sim3 of scale 1e-110 has
    determinant 1e-330, which underflows to 0, and is refused; one of scale e^300 has
    determinant +∞ and is accepted."""
    corner = matrices[:, -1, -1]
    with np.errstate(over="ignore", under="ignore"):
        determinant = np.linalg.det(matrices[:, :-1, :-1])
    unit_corner = np.abs(corner - 1) <= 1e-4
    bad = ~unit_corner | ~(determinant > 0)

    def why(k: int) -> str:
        if unit_corner[k]:
            return f"determinant {determinant[k]:.3g}"
        return f"a last entry of {corner[k]:.3g}, not 1"

    return bad, why


def information_problems(information: np.ndarray) -> tuple[np.ndarray, Callable[[int], str]]:
    """Which of (n, d, d) information matrices are refused, and why the k-th is: not finite,
    not symmetric (|Ω − Ωᵀ| > 1e-9 max|Ω|), zero, or not positive semi-definite
    (λ_min < −1e-9 max|Ω|). A zero eigenvalue is a direction not measured, as in a
    position-only prior, and is allowed."""
    with np.errstate(invalid="ignore"):
        size = np.abs(information).max(axis=(1, 2))  # NaN or ∞ where an entry is
        asymmetry = np.abs(information - np.swapaxes(information, 1, 2)).max(axis=(1, 2))
    symmetric = np.isfinite(size) & (asymmetry <= 1e-9 * size)
    smallest = np.full(len(information), np.nan)  # fails every comparison where not symmetric
    smallest[symmetric] = np.linalg.eigvalsh(information[symmetric])[:, 0]
    bad = ~(smallest >= -1e-9 * size) | (size == 0)

    def why(k: int) -> str:
        if not np.isfinite(size[k]):
            return "not finite"
        if not symmetric[k]:
            return "not symmetric"
        if size[k] == 0:
            return "zero (it would weigh nothing)"
        return f"not positive semi-definite (λ_min = {smallest[k]:.3g})"

    return bad, why


def start_information(measurements: LieGroup, information: np.ndarray) -> np.ndarray:
    """Each between edge's information on its start node's tangent where its residual is zero,
    Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹): there ∂r/∂δᵢ = −Ad(Z⁻¹) (CONVENTIONS.md)."""
    adjoint = measurements.inverse().adjoint()
    return np.swapaxes(adjoint, 1, 2) @ information @ adjoint


def overflowing_edges(measurements: LieGroup, information: np.ndarray) -> np.ndarray:
    """Which between edges' ``start_information`` overflows: their translation, weighed by
    their information, is too large for double precision (beyond about 1e154 for a unit
    information), so no cost or normal equations can hold them."""
    with np.errstate(over="ignore", invalid="ignore"):
        return ~np.isfinite(start_information(measurements, information)).all(axis=(1, 2))


def information_ranks(information: np.ndarray) -> np.ndarray:
    """rank Ωₖ of each of (n, d, d) information matrices: the directions it weighs (2 for an
    SE2 position-only prior, not 3), counting eigenvalues above the tolerance of
    ``information_problems``."""
    if not len(information):
        return np.zeros(0, dtype=int)
    eigenvalues = np.linalg.eigvalsh(information)
    return np.count_nonzero(eigenvalues > 1e-9 * eigenvalues[:, -1:], axis=1)


def measured_dof(information: np.ndarray) -> int:
    """Σ rank Ωₖ over (n, d, d) information matrices (``information_ranks``)."""
    return int(information_ranks(information).sum())


@dataclasses.dataclass(frozen=True, eq=False)
class EdgeSet:
    """Stacked edges of one kind. For priors, ``j`` is unused and equals ``i``."""

    i: np.ndarray
    j: np.ndarray
    measurements: LieGroup
    information: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def empty(cls, group: type[LieGroup]) -> EdgeSet:
        d = group.dof
        empty_index = np.zeros(0, dtype=np.int64)
        return cls(empty_index, empty_index, group.identity((0,)), np.zeros((0, d, d)))

    @staticmethod
    def joined(sets: list[EdgeSet]) -> EdgeSet:
        """The edge sets end to end, in order."""
        group = type(sets[0].measurements)
        return EdgeSet(
            np.concatenate([edges.i for edges in sets]),
            np.concatenate([edges.j for edges in sets]),
            group.concatenate([edges.measurements for edges in sets]),
            np.concatenate([edges.information for edges in sets]),
        )

    def extended(self, other: EdgeSet) -> EdgeSet:
        return EdgeSet.joined([self, other])

    def starts_with(self, other: EdgeSet) -> bool:
        """Whether the first ``len(other)`` edges are exactly ``other``'s."""
        count = len(other)
        return (
            count <= len(self)
            and np.array_equal(self.i[:count], other.i)
            and np.array_equal(self.j[:count], other.j)
            and np.array_equal(self.information[:count], other.information)
            and self.measurements[:count].same_as(other.measurements)
        )

    def subset(self, keep: np.ndarray) -> EdgeSet:
        return EdgeSet(self.i[keep], self.j[keep], self.measurements[keep], self.information[keep])

    def reindexed(self, index: np.ndarray) -> EdgeSet:
        """The same measurements on nodes renumbered by ``index`` (old index → new)."""
        return dataclasses.replace(self, i=index[self.i], j=index[self.j])

    def weighted(self, weights: np.ndarray) -> EdgeSet:
        """The edges of positive weight, each information matrix times its weight."""
        kept = weights > 0
        kept_edges = self.subset(kept)
        return dataclasses.replace(
            kept_edges, information=kept_edges.information * weights[kept, None, None]
        )


@dataclasses.dataclass(frozen=True, eq=False)
class Solution:
    """What ``posegraph.optimize`` left in a graph's values: the optimum over these between
    edges and priors, with each one's weight there (1 in least squares; a robust kernel's IRLS
    weight ρ′(s), 0 for a measurement that graduated non-convexity rejected)."""

    edges: EdgeSet
    priors: EdgeSet
    edge_weights: np.ndarray
    prior_weights: np.ndarray
    fixed: np.ndarray
    """Which of the nodes then in the graph were held."""
    values: LieGroup
    """The values it left, one per node then in the graph."""
    summary: Summary
    """The summary of the call that left them (whether it converged, the cost there, …)."""
    gnc: tuple[str, np.ndarray] | None = None
    """The robust problem whose graduated non-convexity ran to its end here: the kernel's label
    and which measurements were under it (the between edges, then the priors where they were
    too); None in least squares, with an IRLS kernel, or where the run stopped early. A later
    call may carry its decisions (``posegraph.api``)."""
    optimal: bool = True
    """Whether ``values`` are the optimum over ``edges`` and ``priors``: False once a removal
    left what remains of it (``without``), so that a later call solves again."""

    def without(self, nodes: np.ndarray, edges: np.ndarray, priors: np.ndarray) -> Solution:
        """What remains of this solution once the nodes, edges and priors where these masks
        (over its own) hold were removed: the other measurements, renumbered, with their
        weights, rejections and GNC problem, and the values and holds of the other nodes. The
        values are no longer an optimum (``optimal``)."""
        index = _renumbered(~nodes)
        summary = dataclasses.replace(
            self.summary,
            rejected_edges=_kept_indices(self.summary.rejected_edges, edges),
            rejected_priors=_kept_indices(self.summary.rejected_priors, priors),
        )
        gnc = None
        if self.gnc is not None:  # its mask covers the edges, then the priors if they were in
            label, measured = self.gnc
            gnc = (label, measured[np.concatenate([~edges, ~priors])[: measured.size]])
        return Solution(
            self.edges.subset(~edges).reindexed(index),
            self.priors.subset(~priors).reindexed(index),
            self.edge_weights[~edges],
            self.prior_weights[~priors],
            self.fixed[~nodes],
            self.values[~nodes],
            summary,
            gnc,
            optimal=False,
        )

    def weights_for(self, edges: EdgeSet, priors: EdgeSet) -> tuple[np.ndarray, np.ndarray]:
        """The weights of ``edges`` and of ``priors``: the solution's for the measurements it was
        found over, if they still come first and unchanged, and 1 for those added since (1 for
        all of a kind if some of it were changed, or removed other than by ``PoseGraph``'s
        removals, which carry the solution: ``without``)."""
        return (
            _carried(edges, self.edges, self.edge_weights, 1.0),
            _carried(priors, self.priors, self.prior_weights, 1.0),
        )

    def rejected_for(self, edges: EdgeSet, priors: EdgeSet) -> tuple[np.ndarray, np.ndarray]:
        """Masks over ``edges`` and over ``priors`` of the measurements that this solution's
        robust run rejected (``summary.rejected_edges`` and ``rejected_priors``), by the rule of
        ``weights_for``: none of those added since (none of a kind if some of it were changed,
        or removed other than by ``PoseGraph``'s removals)."""
        rejected = []
        for measured, solved, indices in (
            (edges, self.edges, self.summary.rejected_edges),
            (priors, self.priors, self.summary.rejected_priors),
        ):
            flags = np.zeros(len(solved), dtype=bool)
            flags[indices] = True
            rejected.append(_carried(measured, solved, flags, False))
        return rejected[0], rejected[1]


def _renumbered(kept: np.ndarray) -> np.ndarray:
    """Per entry of a sequence, its index among the ``kept`` ones (a mask), or −1."""
    index = np.full(kept.size, -1, dtype=np.int64)
    index[kept] = np.arange(np.count_nonzero(kept))
    return index


def _kept_indices(indices: list[int], removed: np.ndarray) -> list[int]:
    """``indices`` into a sequence, renumbered for the sequence without the ``removed`` ones."""
    renumbered = _renumbered(~removed)
    return [int(renumbered[k]) for k in indices if not removed[k]]


def measurement_mask(given, count: int, noun: str, what: str) -> np.ndarray:
    """A new boolean mask over ``count`` measurements (``noun``: "edge" or "prior") from their
    indices (negative ones count from the end, as in Python) or from a boolean mask with one
    entry per measurement. Anything else is a ``ValueError`` that names ``what`` was chosen
    ("edges to remove", "robust edges") and what is wrong."""
    given = np.asarray(given)
    if given.dtype == bool:
        if given.shape != (count,):
            raise ValueError(
                f"{what} given as a mask have one entry per {noun} ({count}), not shape "
                f"{given.shape}"
            )
        return given.copy()
    indices = np.atleast_1d(given)
    if indices.ndim != 1 or (indices.size and indices.dtype.kind not in "iu"):
        raise ValueError(
            f"{what} are given by integer indices or a boolean mask, not by {given.dtype} of "
            f"shape {given.shape}"
        )
    outside = (indices < -count) | (indices >= count)
    if outside.any():
        raise ValueError(
            f"{noun} index {indices[outside][0]} is out of range ({what}): the graph has "
            f"{count} {noun}s"
        )
    mask = np.zeros(count, dtype=bool)
    mask[indices.astype(np.int64)] = True
    return mask


def _carried(measured: EdgeSet, solved: EdgeSet, values: np.ndarray, added) -> np.ndarray:
    """``values`` (one per solved measurement) for ``measured``, if it starts with exactly the
    ``solved`` ones; ``added`` for those after them, and for all if it does not."""
    carried = np.full(len(measured), added, dtype=values.dtype)
    if measured.starts_with(solved):
        carried[: len(solved)] = values
    return carried


class _Stacked:
    """A stacked value (an array, group elements or an ``EdgeSet``) and the parts appended to
    it since it was last read. Appending costs O(1); the first read joins them all at once.
    Joining at every append made a loop that adds one node and edge at a time quadratic: 2.4 ms
    per node and edge at 50,000 nodes."""

    __slots__ = ("_value", "_parts", "_join", "length")

    def __init__(self, value, join: Callable[[list], object]) -> None:
        self._join = join
        self.set(value)

    def set(self, value) -> None:
        self._value, self._parts, self.length = value, [], len(value)

    def append(self, part) -> None:
        self._parts.append(part)
        self.length += len(part)

    def get(self):
        if self._parts:
            self._value, self._parts = self._join([self._value, *self._parts]), []
        return self._value


def _stacked(name: str, doc: str | None = None) -> property:
    """A ``PoseGraph`` attribute kept in ``_stacks[name]``."""
    return property(
        lambda graph: graph._stacks[name].get(),
        lambda graph, value: graph._stacks[name].set(value),
        doc=doc,
    )


class PoseGraph:
    """A pose graph over one group (SE2, SE3 or Sim3)."""

    node_ids = _stacked("node_ids")
    values = _stacked("values")
    edges = _stacked("edges")
    priors = _stacked("priors")
    fixed = _stacked("fixed")
    initialized = _stacked(
        "initialized", "Which nodes have values (nodes added without one get them when optimised)."
    )

    def __init__(self, group: type[LieGroup] | str) -> None:
        """``group``: SE2, SE3 or Sim3, the class or its name."""
        group = {g.__name__: g for g in POSE_GROUPS}.get(group, group)
        if group not in POSE_GROUPS:
            names = ", ".join(g.__name__ for g in POSE_GROUPS)
            raise ValueError(
                f"a pose graph holds one of {names}, not {getattr(group, '__name__', repr(group))}"
            )
        self.group = group
        self._stacks = {
            "node_ids": _Stacked(np.zeros(0, dtype=np.int64), np.concatenate),
            "values": _Stacked(group.identity((0,)), group.concatenate),
            "edges": _Stacked(EdgeSet.empty(group), EdgeSet.joined),
            "priors": _Stacked(EdgeSet.empty(group), EdgeSet.joined),
            "fixed": _Stacked(np.zeros(0, dtype=bool), np.concatenate),
            "initialized": _Stacked(np.zeros(0, dtype=bool), np.concatenate),
        }
        self.solution: Solution | None = None
        """What ``posegraph.optimize`` left in ``values`` (None if it did not): a warm start
        tests the measurements added since against it, and covariances take its edge weights."""
        self.last_result = None
        """The last ``posegraph.optimize`` result and the structure it was solved for: warm
        starts reuse its normal equations and linearisation."""
        self.equivalences = np.zeros((0, 2), dtype=np.int64)
        """TORO ``EQUIV`` pairs of node ids: kept for round trips, not constraints (as gtsam)."""
        self._index_of: dict[int, int] = {}
        self._components: tuple | None = None
        """(node count, edge end arrays, labels) of the last ``components`` call."""
        self.structure_version = 0
        """Incremented by every change that alters the sparsity pattern or the gauge."""

    def __copy__(self) -> PoseGraph:
        """``copy.copy`` gives ``copy()``: a shallow copy would share the id index and the parts
        still to be joined, so that what is added to one would show in the other."""
        return self.copy()

    def __getstate__(self) -> dict:
        """Pickled and deep-copied without ``last_result``: its factorisation holds CHOLMOD
        handles that cannot be pickled. A copy still warm-starts from its values."""
        return {**self.__dict__, "last_result": None}

    # ------------------------------------------------------------------------ queries
    def current_system(self, linear_solver: str):
        """The normal equations (``NormalEquations``) of the last ``posegraph.optimize`` solved
        on this graph (least squares or an IRLS kernel) with ``linear_solver``, if the graph's
        structure has not changed since (their pattern and symbolic factorisation still hold);
        else None."""
        system = self.last_system(linear_solver)
        if system is None or self.last_result[0][0] != self.structure_version:
            return None
        return system

    def last_system(self, linear_solver: str):
        """The normal equations of the last ``posegraph.optimize`` solved on this graph with
        ``linear_solver``, whatever changed since (a pattern that new ones may grow from:
        ``BlockPattern``), or None."""
        if self.last_result is None:
            return None
        (_, backend), result = self.last_result
        return result.system if backend == linear_solver else None

    def current_normal_matrix(self, values, linear_solver: str) -> np.ndarray | None:
        """H's CSC data at ``values``, in the pattern of ``current_system(linear_solver)``, if
        the last least-squares ``posegraph.optimize`` assembled it there (at its solution,
        when it stopped after a linearisation) and the graph's measurements are those it
        solved; else None."""
        if self.current_system(linear_solver) is None:
            return None
        return self.last_result[1].linearization.normal_matrix_for(self, values)

    @property
    def optimized(self) -> bool:
        """Whether ``values`` holds a solution of ``posegraph.optimize`` (it warm-starts)."""
        return self.solution is not None

    @property
    def num_nodes(self) -> int:
        return self._stacks["node_ids"].length

    @property
    def num_edges(self) -> int:
        return self._stacks["edges"].length

    def __repr__(self) -> str:
        return (
            f"PoseGraph({self.group.__name__}, {self.num_nodes} nodes, {self.num_edges} edges, "
            f"{len(self.priors)} priors, {int(self.fixed.sum())} fixed)"
        )

    def has_node(self, node_id: int) -> bool:
        return int(node_id) in self._index_of

    def index(self, node_ids: Iterable[int] | np.ndarray | int) -> np.ndarray:
        """Indices of node ids; raises ``KeyError`` naming the first unknown id."""
        ids = node_id_array(node_ids)
        try:
            return np.fromiter((self._index_of[k] for k in ids.tolist()), np.int64, ids.size)
        except KeyError as error:
            raise KeyError(f"node {error.args[0]} is not in the graph") from None

    def values_of(self, node_ids) -> LieGroup:
        """The current values of some nodes, stacked in the order given."""
        return self.values[self.index(node_ids)]

    def matrices(self, node_ids=None) -> np.ndarray:
        """(k, n, n) matrices of the values of ``node_ids`` (all nodes if None)."""
        values = self.values if node_ids is None else self.values_of(node_ids)
        return values.as_matrix()

    def positions(self, node_ids=None) -> np.ndarray:
        """(k, 2 or 3) translations of the values of ``node_ids`` (all nodes if None)."""
        values = self.values if node_ids is None else self.values_of(node_ids)
        return np.array(values.translation)

    def _elements(self, values, count: int, describe: Callable[[int], str]) -> LieGroup:
        """``count`` elements of the group from elements or (…, n, n) matrices (one is
        broadcast). Either is refused if it is not finite, if its linear block has determinant
        ≤ 0 (a Sim3 of scale 0, say), or if it is off the group by more than 1e-4 (relative to its
        linear block). Matrices are normalised: rounding drift is projected away; elements are
        kept as they are. A refusal is a ``ValueError`` naming ``describe(k)`` for the k-th."""
        group, n = self.group, self.group.matrix_size
        element = isinstance(values, LieGroup)
        if element:
            if not isinstance(values, group):
                raise TypeError(
                    f"values are {type(values).__name__}, the graph is {group.__name__}"
                )
            if values.batch_shape not in ((), (count,)):
                stacked = f" (or {count})" if count > 1 else ""
                raise ValueError(
                    f"{group.__name__} elements are one{stacked}, not of batch shape "
                    f"{values.batch_shape}"
                )
            values = values if values.batch_shape == (count,) else values.broadcast_to((count,))
            given = values.as_matrix()
        else:
            given = np.asarray(values, float)
            if given.shape not in ((n, n), (count, n, n)):
                stacked = f" (or {count} × {n} × {n})" if count > 1 else ""
                raise ValueError(
                    f"{group.__name__} matrices are {n} × {n}{stacked}, not of shape {given.shape}"
                )
            given = np.broadcast_to(given, (count, n, n))
        finite = np.isfinite(given).all(axis=(1, 2))
        if not finite.all():
            raise ValueError(f"{describe(int(np.flatnonzero(~finite)[0]))} is not finite")
        degenerate, why = element_problems(given)
        if degenerate.any():  # refused before the projection, which needs det > 0
            k = int(np.flatnonzero(degenerate)[0])
            raise ValueError(
                f"{describe(k)} is not an element of {group.__name__} (its matrix has {why(k)})"
            )
        linear = given[:, :-1, :-1]
        normalized = group.from_matrix(given).normalize()
        off = np.abs(normalized.as_matrix() - given).max(axis=(1, 2))
        bad = np.flatnonzero(off > 1e-4 * np.maximum(np.abs(linear).max(axis=(1, 2)), 1))
        if bad.size:
            k = int(bad[0])
            raise ValueError(
                f"{describe(k)} is not an element of {group.__name__} (its matrix is off the "
                f"group by {off[k]:.3g})"
            )
        return values if element else normalized

    # ------------------------------------------------------------------------ growth
    def add_nodes(self, node_ids, values: LieGroup | np.ndarray | None = None) -> np.ndarray:
        """Add nodes (ids must be new and unique); returns their indices.

        ``values`` are group elements or (k, n, n) matrices. Without values, the nodes are
        initialised when the graph is optimised, by composing measurements from nodes that have
        values (as a back end adds a pose with only its odometry edge).
        """
        ids = node_id_array(node_ids)
        has_values = values is not None
        values = (
            self._elements(values, ids.size, lambda k: f"the value of node {ids[k]}")
            if has_values
            else self.group.identity(ids.shape)
        )
        unique, counts = np.unique(ids, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"node id {unique[counts > 1][0]} is given twice")
        clashes = [k for k in ids.tolist() if k in self._index_of]
        if clashes:
            raise ValueError(f"node {clashes[0]} is already in the graph")
        start = self.num_nodes
        indices = np.arange(start, start + ids.size)
        self._index_of.update(zip(ids.tolist(), indices.tolist(), strict=True))
        stacks = self._stacks
        stacks["node_ids"].append(ids)
        stacks["values"].append(values)
        stacks["fixed"].append(np.zeros(ids.size, dtype=bool))
        stacks["initialized"].append(np.full(ids.size, has_values))
        self.structure_version += 1
        return indices

    def add_node(self, node_id: int, value: LieGroup | np.ndarray | None = None) -> int:
        """Add one node (see ``add_nodes``); returns its index."""
        return int(self.add_nodes([node_id], value)[0])

    def _information(self, information, count: int, describe: Callable[[int], str]) -> np.ndarray:
        """(count, d, d) information from one (d, d) or (count, d, d), each passing
        ``information_problems``; else ``ValueError`` names ``describe(k)`` for the k-th."""
        d = self.group.dof
        information = np.asarray(information, float)
        if information.shape not in ((d, d), (count, d, d)):
            stacked = f" (or {count} × {d} × {d} for {count} measurements)" if count > 1 else ""
            raise ValueError(
                f"information must be {d} × {d} for {self.group.__name__}{stacked}, "
                f"not of shape {information.shape}"
            )
        information = np.broadcast_to(information, (count, d, d)).copy()
        bad, why = information_problems(information)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(f"{describe(k)} is {why(k)}")
        return information

    def _edge_set(self, i_ids, j_ids, measurements, information) -> EdgeSet:
        """Measurements on nodes i → j, or priors on nodes i if ``j_ids`` is None."""
        i = self.index(i_ids)
        j = None if j_ids is None else self.index(j_ids)
        if j is not None and i.size != j.size:
            raise ValueError(f"edges need as many i as j ids, not {i.size} and {j.size}")

        def on(k: int) -> str:
            ids = self.node_ids
            return f"prior on node {ids[i[k]]}" if j is None else f"edge {ids[i[k]]} → {ids[j[k]]}"

        measurements = self._elements(
            measurements, i.size, lambda k: f"the measurement of the {on(k)}"
        )
        information = self._information(
            information, i.size, lambda k: f"the information of the {on(k)}"
        )
        return EdgeSet(i, i if j is None else j, measurements, information)

    def add_edges(self, i_ids, j_ids, measurements, information) -> np.ndarray:
        """Add between edges i → j measuring Z ≈ Xᵢ⁻¹ Xⱼ (elements or (k, n, n) matrices) with
        (k, d, d) or one (d, d) information; returns their edge indices."""
        new = self._edge_set(i_ids, j_ids, measurements, information)
        if np.any(new.i == new.j):
            raise ValueError(f"self-loop on node {self.node_ids[new.i[new.i == new.j][0]]}")
        overflowing = np.flatnonzero(overflowing_edges(new.measurements, new.information))
        if overflowing.size:
            i, j = self.node_ids[new.i[overflowing[0]]], self.node_ids[new.j[overflowing[0]]]
            raise ValueError(
                f"the edge {i} → {j}: its translation weighed by its information overflows "
                f"(Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) at node {i}); it is too large for double precision"
            )
        start = self.num_edges
        self._stacks["edges"].append(new)
        self.structure_version += 1
        return np.arange(start, start + len(new))

    def add_edge(self, i_id: int, j_id: int, measurement, information) -> int:
        """Add one between edge (see ``add_edges``); returns its index."""
        return int(self.add_edges([i_id], [j_id], measurement, information)[0])

    def add_priors(self, node_ids, measurements, information) -> np.ndarray:
        """Add priors Z ≈ Xᵢ; returns their prior indices."""
        new = self._edge_set(node_ids, None, measurements, information)
        start = self._stacks["priors"].length
        self._stacks["priors"].append(new)
        self.structure_version += 1
        return np.arange(start, start + len(new))

    def add_prior(self, node_id: int, measurement, information) -> int:
        """Add one prior (see ``add_priors``); returns its index."""
        return int(self.add_priors([node_id], measurement, information)[0])

    def with_edges(self, keep: np.ndarray) -> PoseGraph:
        """A copy holding only the between edges where ``keep`` (a mask or indices) holds."""
        other = self.copy()
        other.edges = self.edges.subset(keep)
        other.structure_version += 1
        return other

    def rejected(self) -> tuple[np.ndarray, np.ndarray]:
        """Masks over the between edges and over the priors of those that the last robust
        ``optimize`` rejected (``Solution.rejected_for``: none added since); none without one."""
        if self.solution is None:
            return np.zeros(self.num_edges, dtype=bool), np.zeros(len(self.priors), dtype=bool)
        return self.solution.rejected_for(self.edges, self.priors)

    def without_rejected(self) -> PoseGraph:
        """A copy without the between edges and priors that the last robust ``optimize``
        rejected (``rejected``): the inliers, to keep, to write or to solve in least squares."""
        edges, priors = self.rejected()
        other = self.with_edges(~edges)
        other.priors = self.priors.subset(~priors)
        return other

    def weighted(self, weights: np.ndarray, prior_weights: np.ndarray | None = None) -> PoseGraph:
        """A copy with each between edge's information times its weight, and each prior's times
        its ``prior_weights`` (if given); those of weight 0 are left out (an edge would join
        components without information)."""
        other = self.copy()
        other.edges = self.edges.weighted(weights)
        if prior_weights is not None:
            other.priors = self.priors.weighted(prior_weights)
        other.structure_version += 1
        return other

    def subgraph(self, nodes: np.ndarray, edges: np.ndarray | None = None) -> PoseGraph:
        """The nodes where the mask ``nodes`` holds (in order, with their values, fixed flags
        and priors) and the between edges joining two of them (only those where the mask
        ``edges`` holds, if given)."""
        index = _renumbered(nodes)
        inside = (index[self.edges.i] >= 0) & (index[self.edges.j] >= 0)
        kept = self.edges.subset(inside if edges is None else inside & edges)
        priors = self.priors.subset(index[self.priors.i] >= 0)
        other = PoseGraph(self.group)
        other.node_ids = self.node_ids[nodes]
        other.values = self.values[nodes]
        other.fixed = self.fixed[nodes]
        other.initialized = self.initialized[nodes]
        other._index_of = dict(zip(other.node_ids.tolist(), range(other.num_nodes), strict=True))
        other.edges = kept.reindexed(index)
        other.priors = priors.reindexed(index)
        inside_pairs = np.isin(self.equivalences, other.node_ids).all(axis=1)
        other.equivalences = self.equivalences[inside_pairs]
        return other

    def remove_edges(self, edges) -> None:
        """Remove between edges given by index (negative ones count from the end) or where a
        boolean mask over the edges holds; indices of later edges shift down. The last
        solution's weights and rejections stay with the edges that remain (``Solution.without``)."""
        removed = measurement_mask(edges, self.num_edges, "edge", "edges to remove")
        self._carry_solution(edges=removed)
        self.edges = self.edges.subset(~removed)
        self.structure_version += 1

    def remove_priors(self, priors) -> None:
        """Remove priors given by index (negative ones count from the end) or where a boolean
        mask over the priors holds (a GNSS fix found wrong); indices of later priors shift
        down. The last solution's weights and rejections stay with the priors that remain."""
        removed = measurement_mask(priors, len(self.priors), "prior", "priors to remove")
        self._carry_solution(priors=removed)
        self.priors = self.priors.subset(~removed)
        self.structure_version += 1

    def remove_nodes(self, node_ids) -> tuple[np.ndarray, np.ndarray]:
        """Remove nodes (ids) with every between edge and prior on them, as g2o's
        ``removeVertex`` does (a back end culling a keyframe); ``KeyError`` names an id not in
        the graph, and nothing is removed then. The other nodes keep their values, ids, holds
        and order; indices of later nodes, edges and priors shift down. Returns masks over the
        edges and over the priors as they were: those removed with the nodes.

        A node that joined parts of the graph leaves them apart unless an edge re-links them
        (for a culled keyframe, the composition of the two edges through it, its information
        from ``lie.uncertainty.compose_covariance``). The next ``posegraph.optimize`` starts
        from the values that remain, and a robust one from the last run's decisions on the
        measurements that remain (``Solution.without``)."""
        removed = np.zeros(self.num_nodes, dtype=bool)
        removed[self.index(node_ids)] = True
        edges = removed[self.edges.i] | removed[self.edges.j]
        priors = removed[self.priors.i]
        self._carry_solution(removed, edges, priors)
        remaining = self.subgraph(~removed)
        for name, stack in self._stacks.items():
            stack.set(getattr(remaining, name))
        self._index_of = remaining._index_of
        self.equivalences = remaining.equivalences
        self.structure_version += 1
        return edges, priors

    def _carry_solution(
        self,
        nodes: np.ndarray | None = None,
        edges: np.ndarray | None = None,
        priors: np.ndarray | None = None,
    ) -> None:
        """Before a removal (masks over the nodes, edges and priors; None for none of them),
        leave in ``solution`` what remains of it (``Solution.without``), if its measurements
        still come first and unchanged; otherwise no later call carries it anyway."""
        solution = self.solution
        if solution is None or not (
            self.edges.starts_with(solution.edges) and self.priors.starts_with(solution.priors)
        ):
            return

        def own(removed: np.ndarray | None, count: int) -> np.ndarray:
            return np.zeros(count, dtype=bool) if removed is None else removed[:count]

        self.solution = solution.without(
            own(nodes, len(solution.fixed)),
            own(edges, len(solution.edges)),
            own(priors, len(solution.priors)),
        )

    def fix(self, node_ids, fixed: bool = True) -> None:
        """Hold nodes at their current values (or release them with ``fixed=False``)."""
        self.fixed[self.index(node_ids)] = fixed
        self.structure_version += 1

    def require_values(self, remedy: str) -> None:
        """Raise ``ValueError`` naming (up to five) nodes added without a value, then ``remedy``."""
        if not self.initialized.all():
            missing = self.node_ids[~self.initialized][:5].tolist()
            raise ValueError(f"nodes {missing} have no values; {remedy}")

    def set_values(self, values: LieGroup) -> None:
        """Replace all node values (batch shape (num_nodes,)); every node then has a value."""
        if values.batch_shape != (self.num_nodes,):
            raise ValueError(f"expected {self.num_nodes} values, got {values.batch_shape}")
        self.values = values
        self.initialized = np.ones(self.num_nodes, dtype=bool)

    def copy(self) -> PoseGraph:
        """An independent copy (arrays are copied on the next change, never shared in place)."""
        other = PoseGraph(self.group)
        other.node_ids = self.node_ids.copy()
        other.values = self.values
        other.edges = self.edges
        other.priors = self.priors
        other.fixed = self.fixed.copy()
        other.initialized = self.initialized.copy()
        other.solution = self.solution
        other.equivalences = self.equivalences.copy()
        other._index_of = dict(self._index_of)
        other.structure_version = self.structure_version
        other._components = self._components
        return other

    # ------------------------------------------------------------------------ structure
    def components(self) -> np.ndarray:
        """Connected-component label of every node (edges of either direction connect); a
        read-only array, cached while the nodes and the edges' end arrays stay the same."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        n, i, j = self.num_nodes, self.edges.i, self.edges.j
        cached = self._components
        if cached is not None and cached[0] == n and cached[1] is i and cached[2] is j:
            return cached[3]
        adjacency = coo_matrix((np.ones(i.size), (i, j)), (n, n))
        labels = connected_components(adjacency, directed=False)[1]
        labels.flags.writeable = False
        self._components = (n, i, j, labels)
        return labels

    def gauge_nodes(self) -> np.ndarray:
        """Indices of the nodes held fixed when optimising (CONVENTIONS.md, "Gauge").

        Nodes marked fixed are held. A connected component with no fixed node and no prior
        has its lowest-id node held, which fixes its gauge (and, for Sim3, its scale).
        """
        held = self.fixed.copy()
        held[self.component_roots()[~self.components_in_world_frame()]] = True
        return np.flatnonzero(held)

    def components_in_world_frame(self) -> np.ndarray:
        """Per component label, whether a held node or a prior sets it in the world frame
        (else ``gauge_nodes`` holds its lowest-id node, and its frame is that node's)."""
        return self._components_holding(self.fixed) | self._components_holding(self.priors.i)

    def components_set_by_priors(self) -> np.ndarray:
        """Per component label, whether its priors set its gauge: it has priors and no fixed
        node, so no node of it is held."""
        return self._components_holding(self.priors.i) & ~self._components_holding(self.fixed)

    def _components_holding(self, nodes: np.ndarray) -> np.ndarray:
        """Per component label, whether the component holds one of ``nodes`` (indices or mask)."""
        labels = self.components()
        holding = np.zeros(labels.max(initial=-1) + 1, dtype=bool)
        holding[labels[nodes]] = True
        return holding

    def component_roots(self) -> np.ndarray:
        """Index of the lowest-id node of each connected component, in label order."""
        labels = self.components()
        order = np.lexsort((self.node_ids, labels))
        return order[np.diff(labels[order], prepend=-1) != 0]
