"""``PoseGraph``: nodes on one Lie group, between edges, priors, and fixed nodes.

Node ids are arbitrary integers; internally every array refers to nodes by their *index*, the
order in which they were added. Edges are stored stacked: index arrays ``i``, ``j``, stacked
measurements and (…, d, d) information matrices over the tangent of CONVENTIONS.md.
A between edge i → j measures Z ≈ Xᵢ⁻¹ Xⱼ; a prior on i measures Z ≈ Xᵢ.

The graph grows in place (``add_nodes``, ``add_edges``, ``add_priors``, ``fix``), shrinks
(``remove_edges``, ``remove_priors``, ``remove_nodes``) and keeps its values, so a back end can
edit it and optimise again. It holds data only: what a solver reuses between calls lives in the
``posegraph.Smoother`` that owns it.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..lie import SE2, SE3, LieGroup, Sim3
from .checks import as_elements, as_information, indices_of, node_id_array, refuse_overflowing
from .components import connected_components
from .edges import EdgeSet, measurement_mask, renumbered
from .stacked import Stacked

POSE_GROUPS: tuple[type[LieGroup], ...] = (SE2, SE3, Sim3)


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
            "node_ids": Stacked(np.zeros(0, dtype=np.int64)),
            "values": Stacked(group.identity((0,))),
            "edges": Stacked(EdgeSet.empty(group)),
            "priors": Stacked(EdgeSet.empty(group)),
            "fixed": Stacked(np.zeros(0, dtype=bool)),
            "initialized": Stacked(np.zeros(0, dtype=bool)),
        }
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
        return indices_of(node_id_array(node_ids), self.node_ids, self._index_of)

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
            as_elements(self.group, values, ids.size, lambda k: f"the value of node {ids[k]}")
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

    def _edge_set(self, i_ids, j_ids, measurements, information) -> EdgeSet:
        """Measurements on nodes i → j, or priors on nodes i if ``j_ids`` is None."""
        i = self.index(i_ids)
        j = None if j_ids is None else self.index(j_ids)
        if j is not None and i.size != j.size:
            raise ValueError(f"edges need as many i as j ids, not {i.size} and {j.size}")

        def on(k: int) -> str:
            ids = self.node_ids
            return f"prior on node {ids[i[k]]}" if j is None else f"edge {ids[i[k]]} → {ids[j[k]]}"

        measurements = as_elements(
            self.group, measurements, i.size, lambda k: f"the measurement of the {on(k)}"
        )
        information = as_information(
            self.group, information, i.size, lambda k: f"the information of the {on(k)}"
        )
        return EdgeSet(i, i if j is None else j, measurements, information)

    def add_edges(self, i_ids, j_ids, measurements, information) -> np.ndarray:
        """Add between edges i → j measuring Z ≈ Xᵢ⁻¹ Xⱼ (elements or (k, n, n) matrices) with
        (k, d, d) or one (d, d) information; returns their edge indices."""
        new = self._edge_set(i_ids, j_ids, measurements, information)
        if np.any(new.i == new.j):
            raise ValueError(f"self-loop on node {self.node_ids[new.i[new.i == new.j][0]]}")
        refuse_overflowing(new, "edge", self._node_id)
        start = self.num_edges
        self._stacks["edges"].append(new)
        self.structure_version += 1
        return np.arange(start, start + len(new))

    def _node_id(self, index: int) -> int:
        return int(self.node_ids[index])

    def add_edge(self, i_id: int, j_id: int, measurement, information) -> int:
        """Add one between edge (see ``add_edges``); returns its index."""
        return int(self.add_edges([i_id], [j_id], measurement, information)[0])

    def add_priors(self, node_ids, measurements, information) -> np.ndarray:
        """Add priors Z ≈ Xᵢ; returns their prior indices."""
        new = self._edge_set(node_ids, None, measurements, information)
        refuse_overflowing(new, "prior", self._node_id)
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
        index = renumbered(nodes)
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
        boolean mask over the edges holds; indices of later edges shift down. A ``Smoother``'s
        ``remove_edges`` does this and keeps its last solution for the edges that remain."""
        removed = measurement_mask(edges, self.num_edges, "edge", "edges to remove")
        self.edges = self.edges.subset(~removed)
        self.structure_version += 1

    def remove_priors(self, priors) -> None:
        """Remove priors given by index (negative ones count from the end) or where a boolean
        mask over the priors holds (a GNSS fix found wrong); indices of later priors shift
        down (``Smoother.remove_priors`` keeps its last solution for those that remain)."""
        removed = measurement_mask(priors, len(self.priors), "prior", "priors to remove")
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
        from ``lie.uncertainty.compose_covariance``). ``Smoother.remove_nodes`` does this and
        keeps its last solution, and GNC's decisions, for what remains."""
        removed = np.zeros(self.num_nodes, dtype=bool)
        removed[self.index(node_ids)] = True
        edges = removed[self.edges.i] | removed[self.edges.j]
        priors = removed[self.priors.i]
        remaining = self.subgraph(~removed)
        for name, stack in self._stacks.items():
            stack.set(getattr(remaining, name))
        self._index_of = remaining._index_of
        self.equivalences = remaining.equivalences
        self.structure_version += 1
        return edges, priors

    def fix(self, node_ids, fixed: bool = True) -> None:
        """Hold nodes at their current values (or release them with ``fixed=False``)."""
        self.fixed[self.index(node_ids)] = fixed
        self.structure_version += 1

    def require_values(self, remedy: str) -> None:
        """Raise ``ValueError`` naming (up to five) nodes added without a value, then ``remedy``."""
        if not self.initialized.all():
            missing = self.node_ids[~self.initialized][:5].tolist()
            raise ValueError(f"nodes {missing} have no values; {remedy}")

    def set_values(self, values: LieGroup | np.ndarray, check: bool = True) -> None:
        """Replace all node values (elements or matrices, batch shape (num_nodes,)); every
        node then has a value. They are checked as ``add_nodes`` checks them (finite, on the
        group); ``check=False`` is for values the library computed itself."""
        if isinstance(values, LieGroup) and values.batch_shape != (self.num_nodes,):
            raise ValueError(f"expected {self.num_nodes} values, got {values.batch_shape}")
        if check:
            ids = self.node_ids
            values = as_elements(
                self.group, values, self.num_nodes, lambda k: f"the value of node {ids[k]}"
            )
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
        other.equivalences = self.equivalences.copy()
        other._index_of = dict(self._index_of)
        other.structure_version = self.structure_version
        other._components = self._components
        return other

    # ------------------------------------------------------------------------ structure
    def components(self) -> np.ndarray:
        """Connected-component label of every node (edges of either direction connect); a
        read-only array, cached while the nodes and the edges' end arrays stay the same."""
        n, i, j = self.num_nodes, self.edges.i, self.edges.j
        cached = self._components
        if cached is not None and cached[0] == n and cached[1] is i and cached[2] is j:
            return cached[3]
        labels = connected_components(n, i, j)
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
