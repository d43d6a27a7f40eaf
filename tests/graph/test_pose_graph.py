"""The pose graph as data: editing by arrays or one at a time, the checks of what enters it,
removals, components and subgraphs."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import posegraph
from posegraph.graph import PoseGraph
from posegraph.graph.checks import LOOKED_UP
from posegraph.lie import SE2, SE3, Sim3
from posegraph.problem.factors import between_squares

from ..conftest import random_graph


def test_batch_and_single_editing_with_arrays():
    graph = PoseGraph(SE3)
    values = SE3.exp(np.random.default_rng(80).normal(size=(4, 6)))
    graph.add_nodes([7, 3, 9], values[:3].as_matrix())  # matrices are accepted
    assert graph.add_node(11, values[3]) == 3
    np.testing.assert_allclose(graph.matrices([9, 11]), values[2:].as_matrix())
    np.testing.assert_allclose(graph.positions(), values.translation)
    edge = graph.add_edge(7, 3, values[0].between(values[1]), np.eye(6))
    graph.add_edges([3, 9], [9, 11], values[1:3].between(values[2:]).as_matrix(), np.eye(6))
    assert edge == 0 and graph.num_edges == 3
    assert graph.has_node(7) and not graph.has_node(99)
    assert graph.add_prior(7, values[0], np.eye(6) * 1e4) == 0
    graph.remove_edges([1])
    assert graph.num_edges == 2
    with pytest.raises(KeyError, match="node 99"):
        graph.add_edge(7, 99, values[0], np.eye(6))
    with pytest.raises(ValueError, match="already in the graph"):
        graph.add_node(3, values[0])
    with pytest.raises(TypeError):
        graph.add_node(12, SE2.identity())


def test_a_graph_built_one_node_and_edge_at_a_time_equals_one_built_at_once():
    """Added parts are joined when the graph is next read: reads, copies (``copy.copy`` too)
    and pickles between the additions see every part added so far, and never the later ones."""
    rng = np.random.default_rng(81)
    n = 40
    values = SE3.exp(rng.normal(size=(n, 6)))
    measured = values[:-1].between(values[1:])
    information = np.eye(6) * rng.uniform(1, 9, size=(n - 1, 1, 1))
    at_once = PoseGraph(SE3)
    at_once.add_nodes(np.arange(n), values)
    at_once.add_edges(np.arange(n - 1), np.arange(1, n), measured, information)
    at_once.add_priors([5, 20], values[[5, 20]], np.eye(6))
    one_by_one = PoseGraph(SE3)
    snapshots = {}
    for k in range(n):
        assert one_by_one.add_node(k, values[k]) == k
        if k:
            assert one_by_one.add_edge(k - 1, k, measured[k - 1], information[k - 1]) == k - 1
        if k in (5, 20):
            one_by_one.add_prior(k, values[k], np.eye(6))
        if k % 7 == 3:
            snapshots[k] = (
                one_by_one.copy(),
                copy.copy(one_by_one),
                pickle.loads(pickle.dumps(one_by_one)),
            )
        assert one_by_one.num_nodes == k + 1 and one_by_one.num_edges == k
    for k, taken in snapshots.items():
        for snapshot in taken:
            assert snapshot.num_nodes == k + 1 and len(snapshot.edges) == k
            np.testing.assert_array_equal(snapshot.node_ids, np.arange(k + 1))
            np.testing.assert_allclose(snapshot.values.as_matrix(), values[: k + 1].as_matrix())
    for name in ("node_ids", "fixed", "initialized"):
        np.testing.assert_array_equal(getattr(one_by_one, name), getattr(at_once, name))
    np.testing.assert_array_equal(one_by_one.values.as_matrix(), at_once.values.as_matrix())
    for kind in ("edges", "priors"):
        built, expected = getattr(one_by_one, kind), getattr(at_once, kind)
        assert built.starts_with(expected) and len(built) == len(expected)
    assert posegraph.optimize(one_by_one).summary.final_error == pytest.approx(
        posegraph.optimize(at_once).summary.final_error, abs=1e-12
    )


def test_information_is_checked_where_it_is_given():
    """Shape, finiteness, symmetry and positive semi-definiteness, with the measurement named;
    a zero eigenvalue (a direction not measured, as a position-only prior) is accepted."""
    graph = PoseGraph(SE2)
    graph.add_nodes([4, 5, 6], SE2.identity((3,)))
    z = SE2.identity()
    cases = [
        (np.eye(2), r"must be 3 × 3 for SE2, not of shape \(2, 2\)"),
        (np.diag([1.0, np.nan, 1.0]), "edge 4 → 5 is not finite"),
        (np.diag([1.0, np.inf, 1.0]), "edge 4 → 5 is not finite"),
        (np.triu(np.ones((3, 3))), "edge 4 → 5 is not symmetric"),
        (np.diag([1.0, -2.0, 1.0]), r"edge 4 → 5 is not positive semi-definite \(λ_min = -2\)"),
    ]
    for information, message in cases:
        with pytest.raises(ValueError, match=message):
            graph.add_edge(4, 5, z, information)
    stacked = np.stack([np.eye(3), -np.eye(3)])
    with pytest.raises(ValueError, match="edge 5 → 6 is not positive"):
        graph.add_edges([4, 5], [5, 6], SE2.identity((2,)), stacked)
    with pytest.raises(ValueError, match=r"or 2 × 3 × 3 for 2 measurements"):
        graph.add_edges([4, 5], [5, 6], SE2.identity((2,)), np.ones((3, 3, 3)))
    with pytest.raises(ValueError, match="prior on node 6 is not positive"):
        graph.add_prior(6, z, -np.eye(3))
    assert graph.num_edges == 0 and len(graph.priors) == 0
    graph.add_prior(6, z, np.diag([1.0, 1.0, 0.0]))
    assert len(graph.priors) == 1


def test_values_and_measurements_are_checked_where_they_are_given():
    """Matrices off the group (a transposed pose, a scaled rotation, a wrong last row) or not
    finite are refused with the node or measurement named, and so is an edge whose translation
    weighed by its information overflows; rounding drift is projected away."""
    graph = PoseGraph("SE3")
    pose = SE3.exp(np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])).as_matrix()
    bottom = np.eye(4)
    bottom[3, :3] = 1.0
    cases = [
        (np.eye(3), r"SE3 matrices are 4 × 4, not of shape \(3, 3\)"),
        (pose.T, "the value of node 5 is not an element of SE3"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "the value of node 5 is not an element of SE3"),
        (bottom, "the value of node 5 is not an element of SE3"),
        (np.full((4, 4), np.nan), "the value of node 5 is not finite"),
        (SE3(np.eye(3), np.array([np.inf, 0.0, 0.0])), "the value of node 5 is not finite"),
    ]
    for value, message in cases:
        with pytest.raises(ValueError, match=message):
            graph.add_node(5, value)
    with pytest.raises(ValueError, match="the value of node 8 is not an element"):
        graph.add_nodes([6, 7, 8], np.stack([pose, pose, np.diag([1.0, 1.0, -1.0, 1.0])]))
    assert graph.num_nodes == 0
    graph.add_nodes([5, 6], np.stack([pose + 1e-7, pose]))
    rotation = graph.values.rotation[0]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(rotation, pose[:3, :3], atol=1e-6)
    with pytest.raises(ValueError, match="the measurement of the edge 5 → 6 is not an element"):
        graph.add_edge(5, 6, 2.0 * pose, np.eye(6))
    with pytest.raises(ValueError, match="the measurement of the prior on node 6 is not finite"):
        graph.add_prior(6, np.full((4, 4), np.inf), np.eye(6))
    far = SE3(np.eye(3), np.array([1e160, 0.0, 0.0]))  # finite, but its squares overflow
    with pytest.raises(ValueError, match=r"edge 5 → 6: its translation weighed by its information"):
        graph.add_edge(5, 6, far, np.eye(6))
    assert graph.num_edges == 0
    graph.add_edge(5, 6, far, np.diag([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]))  # rotation only: finite
    with pytest.raises(ValueError, match="a pose graph holds one of SE2, SE3, Sim3, not 'se3'"):
        PoseGraph("se3")


def test_set_values_checks_values_as_add_nodes_does():
    """``set_values`` took NaN or non-orthogonal values that ``add_nodes`` refuses, and
    ``optimize(init="file")`` then returned NaN without raising."""
    graph = random_graph(SE3, 5, 2, seed=12)
    before = graph.values
    nan = graph.values.set_at(2, SE3(np.eye(3), np.array([np.nan, 0.0, 0.0])))
    skewed = graph.values.set_at(4, SE3(np.diag([1.0, 1.0, 1.5]), np.zeros(3)))
    for values, message in [
        (nan, "the value of node 14 is not finite"),
        (skewed, "the value of node 18 is not an element of SE3"),
        (np.full((5, 4, 4), np.inf), "the value of node 10 is not finite"),
    ]:
        with pytest.raises(ValueError, match=message):
            graph.set_values(values)
        assert graph.values is before
    graph.set_values(before.as_matrix() + 1e-9)  # matrices, rounding drift projected away
    result = posegraph.optimize(graph, init="file")
    assert np.isfinite(result.summary.final_error)


def test_elements_are_checked_like_matrices_but_kept_as_given():
    """A group element built from bad parts (a Sim3 of scale 0 or −1, a reflection, a sheared
    rotation) is refused as its matrix would be; one within 1e-4 of the group is kept bit for
    bit, not projected."""
    graph = PoseGraph("Sim3")
    cases = [
        (Sim3(np.eye(3), np.zeros(3), np.array(0.0)), "determinant 0"),
        (Sim3(np.eye(3), np.zeros(3), np.array(-1.0)), "determinant -1"),
        (Sim3(np.diag([1.0, 1.0, -1.0]), np.zeros(3), np.array(2.0)), "determinant -8"),
        (
            Sim3(
                np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
                np.zeros(3),
                np.array(1.0),
            ),
            "off the group by 0.05",
        ),
    ]
    for value, message in cases:
        with pytest.raises(
            ValueError, match=f"the value of node 3 is not an element of Sim3.*{message}"
        ):
            graph.add_node(3, value)
    graph.add_nodes([1, 2])
    with pytest.raises(ValueError, match="the measurement of the edge 1 → 2 is not an element"):
        graph.add_edge(1, 2, cases[0][0], np.eye(7))
    nearly = np.eye(3) + 1e-7
    graph.add_node(3, Sim3(nearly, np.zeros(3), np.array(2.0)))
    assert np.array_equal(graph.values.rotation[-1], nearly)


def test_node_ids_are_whole_numbers_of_at_most_64_bits():
    """Ids loaded as whole floats are taken; a fraction, a string, a boolean, an id beyond 64
    bits or a nested list is refused by name rather than truncated or wrapped."""
    graph = PoseGraph(SE2)
    graph.add_nodes(np.array([3.0, 2.0**62]))
    graph.add_nodes(np.array([2**63 - 1], dtype=np.uint64))
    assert graph.node_ids.tolist() == [3, 2**62, 2**63 - 1]
    assert graph.index([2**63 - 1]).tolist() == [2]
    refused = [
        ([0.5], "node id 0.5 is not an integer"),
        (["a"], "node id 'a' is not an integer"),
        ([True], "node id True is not an integer"),
        ([2**63], "node id 9223372036854775808 is not an integer of at most 64 bits"),
        ([-(2**70)], "node id -1180591620717411303424 is not"),
        (np.array([2**64 - 1], dtype=np.uint64), "node id 18446744073709551615 is not"),
        ([[4, 5]], r"node ids are one sequence of integers, not of shape \(1, 2\)"),
    ]
    for ids, message in refused:
        with pytest.raises(ValueError, match=message):
            graph.add_nodes(ids)
        with pytest.raises(ValueError, match=message):
            graph.index(ids)
    assert graph.num_nodes == 3


def test_many_node_ids_are_indexed_as_one_by_one():
    """Beyond ``LOOKED_UP`` ids, ``index`` searches the sorted node ids: the same indices as
    looked up one by one (ids out of order, negative, up to 2⁶³ − 1, repeated), and the same
    error, naming the first unknown id."""
    rng = np.random.default_rng(5)
    ids = rng.choice(np.arange(-(2**40), 2**40, 2**20), size=300, replace=False)
    ids[7] = 2**63 - 1
    graph = PoseGraph(SE2)
    graph.add_nodes(ids)
    queried = rng.choice(ids, size=LOOKED_UP * 4)
    one_by_one = [int(graph.index([k])[0]) for k in queried.tolist()]
    assert graph.index(queried).tolist() == one_by_one
    assert [ids[k] for k in one_by_one] == queried.tolist()
    unknown = queried.copy()
    unknown[[50, 200]] = [12345, 2**62]
    for many in (unknown, unknown[:LOOKED_UP]):
        with pytest.raises(KeyError, match="node 12345 is not in the graph"):
            graph.index(many)


def test_edges_are_removed_by_index_or_mask_and_counts_must_agree():
    graph = PoseGraph(SE2)
    graph.add_nodes(range(5))
    graph.add_edges([0, 1, 2, 3], [1, 2, 3, 4], SE2.identity(), np.eye(3))
    graph.remove_edges(np.array([True, False, False, True]))
    assert graph.edges.i.tolist() == [1, 2]
    graph.remove_edges(-1)
    assert graph.edges.i.tolist() == [1]
    for edges, message in [
        ([1], r"edge index 1 is out of range \(edges to remove\): the graph has 1 edges"),
        (
            [True, False],
            r"edges to remove given as a mask have one entry per edge \(1\), not shape \(2,\)",
        ),
        ([0.0], r"integer indices or a boolean mask, not by float64 of shape \(1,\)"),
    ]:
        with pytest.raises(ValueError, match=message):
            graph.remove_edges(edges)
    assert graph.num_edges == 1
    with pytest.raises(ValueError, match="as many i as j ids, not 1 and 2"):
        graph.add_edges([0], [1, 2], SE2.identity(), np.eye(3))
    with pytest.raises(
        ValueError, match=r"SE2 elements are one \(or 2\), not of batch shape \(3,\)"
    ):
        graph.add_edges([0, 1], [2, 3], SE2.identity((3,)), np.eye(3))
    assert graph.num_edges == 1


def test_priors_are_removed_by_index_or_mask_and_counts_must_agree():
    graph = random_graph(SE2, 8, 0, seed=84, priors=5)
    before = graph.priors
    graph.remove_priors([1, -1])
    assert graph.priors.i.tolist() == before.i[[0, 2, 3]].tolist()
    assert graph.priors.measurements.same_as(before.measurements[[0, 2, 3]])
    graph.remove_priors(np.array([True, False, True]))
    assert graph.priors.i.tolist() == [before.i[2]]
    for priors, message in [
        ([1], r"prior index 1 is out of range \(priors to remove\): the graph has 1 priors"),
        (
            [True, False],
            r"priors to remove given as a mask have one entry per prior \(1\), not shape \(2,\)",
        ),
        (["0"], "priors to remove are given by integer indices or a boolean mask, not by <U1"),
    ]:
        with pytest.raises(ValueError, match=message):
            graph.remove_priors(priors)
    assert len(graph.priors) == 1 and graph.num_edges == 7


def test_removing_nodes_takes_their_edges_and_priors_and_keeps_the_rest_in_order():
    """What remains is what a graph built without those nodes holds: compared by node id,
    edge by edge and prior by prior, with the masks of what went."""
    graph = random_graph(SE3, 12, 10, seed=83, priors=5)
    ids = graph.node_ids.copy()
    graph.fix(ids[[0, 7]])
    graph.add_node(99)  # without a value
    graph.equivalences = np.array([[ids[1], ids[3]], [ids[2], ids[5]]])
    before = graph.copy()
    culled = ids[[3, 7, 8]]
    edges, priors = graph.remove_nodes([culled[2], culled[0], culled[1], culled[0]])
    gone = np.isin(before.node_ids, culled)
    np.testing.assert_array_equal(edges, gone[before.edges.i] | gone[before.edges.j])
    np.testing.assert_array_equal(priors, gone[before.priors.i])
    assert 0 < edges.sum() < before.num_edges and 0 < priors.sum() < len(before.priors)
    np.testing.assert_array_equal(graph.node_ids, before.node_ids[~gone])
    assert graph.values.same_as(before.values[~gone])
    assert graph.fixed.tolist() == before.fixed[~gone].tolist()
    assert graph.initialized.tolist() == [True] * 9 + [False]
    for now, then, kept in (
        (graph.edges, before.edges, ~edges),
        (graph.priors, before.priors, ~priors),
    ):
        np.testing.assert_array_equal(graph.node_ids[now.i], before.node_ids[then.i[kept]])
        np.testing.assert_array_equal(graph.node_ids[now.j], before.node_ids[then.j[kept]])
        assert now.measurements.same_as(then.measurements[kept])
        np.testing.assert_array_equal(now.information, then.information[kept])
    assert graph.equivalences.tolist() == [[ids[2], ids[5]]]
    assert not graph.has_node(ids[3]) and graph.index([ids[9], 99]).tolist() == [6, 9]
    with pytest.raises(KeyError, match=f"node {ids[3]} is not in the graph"):
        graph.remove_nodes([ids[4], ids[3]])
    assert graph.num_nodes == 10 and graph.has_node(ids[4])
    graph.add_node(ids[3], SE3.identity())  # its id is free again
    assert graph.index(ids[3]) == 10


def test_components_follow_every_edit():
    """``components`` is cached: each edit of nodes or edges must be seen."""
    graph = PoseGraph(SE2)
    graph.add_nodes([0, 1, 2, 3], SE2.identity((4,)))
    graph.add_edges([0, 2], [1, 3], SE2.identity((2,)), np.eye(3))
    assert len(set(graph.components())) == 2
    graph.add_edge(1, 2, SE2.identity(), np.eye(3))
    assert len(set(graph.components())) == 1
    graph.add_node(4)
    assert len(set(graph.components())) == 2
    graph.remove_edges([2])
    assert len(set(graph.components())) == 3
    assert len(set(graph.with_edges(np.array([], dtype=int)).components())) == 5
    assert not graph.components().flags.writeable


def test_components_label_as_scipy_does():
    """numpy's hooking and pointer jumping (``graph.components``) against scipy's
    ``connected_components`` on random multigraphs with self-loops and isolated nodes, and on
    chains numbered forwards, backwards and interleaved (the deepest trees to jump through)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as scipy_components

    from posegraph.graph import connected_components

    rng = np.random.default_rng(0)
    cases = []
    for _ in range(200):
        n = int(rng.integers(1, 200))
        m = int(rng.integers(0, 2 * n))
        cases.append((n, rng.integers(0, n, m), rng.integers(0, n, m)))
    order = np.arange(3000)
    for path in (order, order[::-1], np.concatenate([order[::2], order[1::2][::-1]])):
        cases.append((order.size, path[:-1], path[1:]))
    for n, i, j in cases:
        expected = scipy_components(coo_matrix((np.ones(i.size), (i, j)), (n, n)), directed=False)
        np.testing.assert_array_equal(connected_components(n, i, j), expected[1])


def test_a_subgraph_keeps_its_nodes_in_order_with_the_edges_among_them():
    graph = random_graph(SE2, 10, 6, seed=79, priors=3)
    graph.fix(graph.node_ids[[4]])
    nodes = np.zeros(10, dtype=bool)
    nodes[[1, 2, 4, 7, 8]] = True
    sub = graph.subgraph(nodes)
    np.testing.assert_array_equal(sub.node_ids, graph.node_ids[nodes])
    assert sub.values.same_as(graph.values[nodes])
    assert sub.fixed.tolist() == [False, False, True, False, False]
    inside = nodes[graph.edges.i] & nodes[graph.edges.j]
    ids = graph.node_ids
    expected = set(zip(ids[graph.edges.i[inside]], ids[graph.edges.j[inside]], strict=True))
    assert set(zip(sub.node_ids[sub.edges.i], sub.node_ids[sub.edges.j], strict=True)) == expected
    # The same edges with the same values: the same residuals.
    np.testing.assert_array_equal(
        between_squares(sub.values, sub.edges),
        between_squares(graph.values, graph.edges.subset(inside)),
    )
    prior_inside = nodes[graph.priors.i]
    np.testing.assert_array_equal(sub.node_ids[sub.priors.i], ids[graph.priors.i[prior_inside]])
    np.testing.assert_array_equal(sub.priors.j, sub.priors.i)  # a prior's ends are one node
    chosen = np.zeros(graph.num_edges, dtype=bool)
    chosen[np.flatnonzero(inside)[:2]] = True
    assert sub.num_edges > 2 and graph.subgraph(nodes, edges=chosen).num_edges == 2
