"""The warm start's composition of new nodes: the direct path for a few streamed poses agrees
with the spanning tree's, and its tree test with scipy's connected components."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world

from posegraph.init.spanning_tree import spanning_tree_values
from posegraph.problem.factors import linearize_between
from posegraph.smoother import composition, growth


def test_direct_composition_equals_the_spanning_tree_along_the_same_edges():
    """Nodes 0–29 solved, 30–39 new: each new node's edges include its odometry, and loops to
    older nodes; both paths compose along odometry."""
    graph, _ = manhattan_world(num_poses=40, seed=3)
    new = np.arange(40) >= 30
    expected = spanning_tree_values(graph, known=~new)
    composed = graph.copy()
    assert composition._compose_directly(composed, new)
    for k in range(30, 40):
        np.testing.assert_allclose(
            composed.values[k].as_matrix(), expected[k].as_matrix(), atol=1e-9
        )


def test_direct_composition_declines_what_it_cannot_do():
    graph, _ = manhattan_world(num_poses=40, seed=3)
    unreachable = np.zeros(40, dtype=bool)
    unreachable[[10, 11]] = True
    graph.remove_edges((graph.edges.i == 10) | (graph.edges.j == 10))
    assert not composition._compose_directly(graph, unreachable)  # node 10 hangs off nothing
    many = np.arange(40) >= 40 - composition.DIRECT_COMPOSITION - 1
    assert not composition._compose_directly(graph, many)


@pytest.mark.parametrize("seed", range(20))
def test_the_tree_test_agrees_with_scipys_connected_components(seed):
    """Random edge sets over 3 old nodes and up to 5 new ones: ``_hangs_a_tree`` holds exactly
    where there is one edge per new node and scipy finds the new nodes and the old ones,
    taken as one, connected."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(seed)
    old, new = 3, int(rng.integers(1, 6))
    count = old + new
    i, j = rng.integers(0, count, size=(2, new))
    ends = np.maximum(np.stack([i, j]) - old + 1, 0)  # the old nodes as node 0
    adjacency = scipy.sparse.coo_matrix((np.ones(new), (ends[0], ends[1])), (new + 1, new + 1))
    connected = connected_components(adjacency, directed=False)[0] == 1
    assert growth._hangs_a_tree(i, j, old, count) == connected


def test_one_new_node_is_refined_to_the_local_optimum_of_a_whole_local_solve(monkeypatch):
    """A pose of a world with loops into it, taken as new: ``_refine_one`` ends where the local
    Levenberg-Marquardt solve of ``_local_graph`` ends (run to convergence, from the same
    composed start; 1e-6 on the pose)."""
    from posegraph.solvers import SolverOptions, solve

    graph, _ = manhattan_world(num_poses=120, seed=5)
    degree = np.bincount(np.concatenate([graph.edges.i, graph.edges.j]), minlength=120)
    last = int(np.argmax(degree))
    assert degree[last] >= 3  # odometry both ways and a loop
    new = np.arange(graph.num_nodes) == last
    assert composition._compose_directly(graph, new)
    local, local_new = composition._local_graph(graph, new)
    tight = SolverOptions(relative_decrease=1e-12, max_iterations=50)
    expected = solve(local, tight).values[local_new][0]
    start = graph.values[last].as_matrix()
    assert np.abs(start - expected.as_matrix()).max() > 1e-3  # the loop moves it
    linearisations = []

    def counted(values, edges):
        linearisations.append(len(edges))
        return linearize_between(values, edges)

    monkeypatch.setattr(composition, "linearize_between", counted)
    composition._refine_one(graph, last, 50)
    np.testing.assert_allclose(graph.values[last].as_matrix(), expected.as_matrix(), atol=1e-6)
    # At the start and after the first step; the last step, whose Gauss-Newton model promised
    # less than the tolerance, is taken without linearising there.
    assert len(linearisations) == 2
