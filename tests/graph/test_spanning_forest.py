"""The minimum spanning forest and the rooting of trees, against scipy's ``csgraph``."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

from posegraph.graph import connected_components
from posegraph.graph.spanning_forest import minimum_spanning_forest, rooted


def _multigraphs():
    """Random multigraphs with self-loops, isolated nodes and weights with many ties, and chains
    numbered forwards, backwards and interleaved (the deepest trees to jump through)."""
    rng = np.random.default_rng(0)
    for _ in range(150):
        n = int(rng.integers(1, 150))
        m = int(rng.integers(0, 3 * n))
        yield n, rng.integers(0, n, m), rng.integers(0, n, m), rng.integers(1, 4, m) * 0.5
    order = np.arange(3000)
    for path in (order, order[::-1], np.concatenate([order[::2], order[1::2][::-1]])):
        yield order.size, path[:-1], path[1:], np.ones(order.size - 1)


def _scipy_weight(n: int, i: np.ndarray, j: np.ndarray, weights: np.ndarray) -> float:
    """The weight of scipy's minimum spanning forest, of the lightest edge of each pair."""
    low, high = np.minimum(i, j), np.maximum(i, j)
    keep = np.lexsort((weights, high, low))
    pair = low[keep] * n + high[keep]
    keep = keep[(np.diff(pair, prepend=-1) != 0) & (low[keep] != high[keep])]
    matrix = coo_matrix((weights[keep], (low[keep], high[keep])), shape=(n, n))
    return float(minimum_spanning_tree(matrix).sum())


def test_the_forest_spans_each_component_at_scipys_least_weight():
    for n, i, j, weights in _multigraphs():
        forest = minimum_spanning_forest(n, i, j, weights)
        labels = connected_components(n, i, j)
        assert forest.size == n - (labels.max() + 1)  # a forest: no edge closes a cycle
        np.testing.assert_array_equal(connected_components(n, i[forest], j[forest]), labels)
        assert weights[forest].sum() == pytest.approx(_scipy_weight(n, i, j, weights), abs=1e-12)


def test_equal_weights_take_the_lower_index():
    # a triangle of equal weights and a doubled edge: the forest is the first edges
    i, j = np.array([0, 1, 2, 0, 3]), np.array([1, 2, 0, 3, 0])
    forest = minimum_spanning_forest(4, i, j, np.ones(5))
    np.testing.assert_array_equal(forest, [0, 1, 3])


@pytest.mark.parametrize("seed", range(40))
def test_a_tree_hangs_from_its_root_as_a_breadth_first_search_finds(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    m = 3 * n
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    i, j = np.append(i, np.arange(n - 1)), np.append(j, np.arange(1, n))  # connected
    tree = minimum_spanning_forest(n, i, j, rng.random(i.size))
    i, j = i[tree], j[tree]
    root = int(rng.integers(0, n))
    parent, edge = rooted(n, i, j, root)
    adjacency = coo_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    _, expected = breadth_first_order(adjacency, root, directed=False)
    expected[root] = root
    np.testing.assert_array_equal(parent, expected)
    assert edge[root] == -1
    child = np.flatnonzero(np.arange(n) != root)
    ends = np.sort(np.stack([i[edge[child]], j[edge[child]]], axis=1), axis=1)
    np.testing.assert_array_equal(ends, np.sort(np.stack([child, parent[child]], axis=1), axis=1))


def test_a_long_chain_hangs_from_its_middle():
    n = 5001
    parent, edge = rooted(n, np.arange(n - 1), np.arange(1, n), 2500)
    nodes = np.arange(n)
    np.testing.assert_array_equal(parent[:2500], nodes[1:2501])
    np.testing.assert_array_equal(parent[2501:], nodes[2500:-1])
    np.testing.assert_array_equal(edge[:2500], nodes[:2500])
    np.testing.assert_array_equal(edge[2501:], nodes[2500:-1])
