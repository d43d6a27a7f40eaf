"""Minimum spanning forests and rooted trees of undirected graphs given as edge arrays, in numpy
alone (scipy's ``csgraph`` does the same but brings scipy.sparse's import, longer than a
streamed graph's first solve).

``minimum_spanning_forest`` is Borůvka's algorithm (1926): each round, every component takes
its lightest edge out, ties broken by edge index so that the forest is unique; the chosen edges
hook components together, and pointer jumping (Shiloach & Vishkin 1982) relabels them. Each
round at least halves the components. ``rooted`` orients a tree from a root by the Euler tour
technique (Tarjan & Vishkin 1985): the tour's successor of arc u → v is the arc after v → u
around v, list ranking by pointer jumping numbers the arcs, and an arc leads away from the
root where it comes before its reverse.
"""

from __future__ import annotations

import numpy as np

from .components import roots


def minimum_spanning_forest(
    count: int, i: np.ndarray, j: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """The indices of the edges i — j (of ``weights``) in the minimum spanning forest of
    ``count`` nodes, the lighter of equal weights being the lower index."""
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    by_weight = np.lexsort((np.arange(i.size), weights))
    rank = np.empty(i.size, dtype=np.int64)
    rank[by_weight] = np.arange(i.size)
    label, nodes, chosen = np.arange(count), np.arange(count), np.zeros(i.size, dtype=bool)
    while True:
        a, b = label[i], label[j]
        across = a != b
        if not across.any():
            return np.flatnonzero(chosen)
        lightest = np.full(count, i.size)
        np.minimum.at(lightest, a[across], rank[across])
        np.minimum.at(lightest, b[across], rank[across])
        leaving = np.flatnonzero(lightest < i.size)
        edge = by_weight[lightest[leaving]]
        chosen[edge] = True
        hook = nodes.copy()
        hook[leaving] = np.where(label[i[edge]] == leaving, label[j[edge]], label[i[edge]])
        mutual = (hook[hook] == nodes) & (nodes < hook)  # two components that chose one edge
        hook[mutual] = nodes[mutual]
        label = roots(hook)[label]


def rooted(count: int, i: np.ndarray, j: np.ndarray, root: int) -> tuple[np.ndarray, np.ndarray]:
    """The parent (count,) of each node of the tree of edges i — j that spans ``count`` nodes,
    hung from ``root`` (the root's parent is itself), and the index of the edge joining each
    node to its parent (−1 for the root)."""
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    parent, edge = np.full(count, root, dtype=np.int64), np.full(count, -1, dtype=np.int64)
    m = i.size
    if m == 0:
        return parent, edge
    tail, head = np.concatenate([i, j]), np.concatenate([j, i])
    reverse = np.concatenate([np.arange(m, 2 * m), np.arange(m)])
    around = np.lexsort((head, tail))  # the arcs out of each node, one block per node
    tails = tail[around]
    first_out = np.searchsorted(tails, tails)
    following = np.roll(around, -1)
    block_end = np.append(tails[1:] != tails[:-1], True)
    following[block_end] = around[first_out[block_end]]
    after = np.empty(2 * m, dtype=np.int64)
    after[around] = following  # the next arc out of the same node, cyclically
    successor = after[reverse]
    start = around[np.searchsorted(tails, root)]
    successor[successor == start] = np.flatnonzero(successor == start)  # the tour ends there
    remaining = (successor != np.arange(2 * m)).astype(np.int64)
    while True:
        further = successor[successor]
        if np.array_equal(further, successor):
            break
        remaining += remaining[successor]
        successor = further
    outward = np.flatnonzero(remaining > remaining[reverse])
    parent[head[outward]] = tail[outward]
    edge[head[outward]] = outward % m
    return parent, edge
