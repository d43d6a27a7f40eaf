"""The library API a SLAM back end uses: editing, warm starts, reuse, marginal covariances."""

from __future__ import annotations

import copy
import dataclasses
import importlib
import pickle

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph import sparse_cholesky
from posegraph.api import COMPOSED, DECISIONS_AS_START, RESTART, robust_mask
from posegraph.benchmarks.incremental import arrivals, run, stream
from posegraph.factors import between_squares, linearize_between, linearize_priors
from posegraph.graph import PoseGraph
from posegraph.io import read_graph, write_graph
from posegraph.lie import SE2, SE3, SO3, Sim3
from posegraph.lie.uncertainty import compose_covariance, inverse_covariance
from posegraph.linear import NormalEquations
from posegraph.solvers import STOPPED
from posegraph.sparse_cholesky import COUPLED_COLUMNS, SOLVED_COLUMNS, NotPositiveDefinite

from .conftest import city_with_fixes, cull, random_graph, union


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


def test_after_culling_keyframes_a_warm_start_ends_where_a_fresh_solve_does():
    """Keyframes culled from an optimised map (their neighbours re-linked), and a pose added:
    the warm start ends at a fresh solve's optimum, by least squares and by GNC, and is not
    taken for the old solution extended (the culled nodes' loops changed the problem). GNC's
    rejections stay with the edges that remain, its search starts from its decisions there,
    and it rejects what a fresh GNC rejects: the false loops that remain."""
    clean, _ = manhattan_world(200, seed=3)
    noisy, false = add_false_loops(clean, 0.1, seed=3)
    culled = [60, 94, 130]  # 94 ends a false loop
    ends = noisy.node_ids[noisy.edges.i], noisy.node_ids[noisy.edges.j]
    touching = np.isin(ends[0], culled) | np.isin(ends[1], culled)
    # The edges that remain come first, in order, then the re-links and the new odometry.
    remaining_false = np.flatnonzero(false[~touching])
    for graph, robust in ((clean, None), (noisy, "gnc")):
        posegraph.optimize(graph, robust=robust)
        for node in culled:
            cull(graph, node)
        rejected = np.flatnonzero(graph.rejected()[0])
        assert rejected.tolist() == (remaining_false.tolist() if robust else [])
        graph.add_node(500)
        graph.add_edge(199, 500, SE2.from_xytheta([1.0, 0.0, 0.0]), np.eye(3) * 100)
        warm = posegraph.optimize(graph.copy(), robust=robust).summary
        fresh = posegraph.optimize(graph.copy(), init="chordal", robust=robust).summary
        assert warm.initialization == "warm start" and warm.termination != COMPOSED
        assert _searched_from_decisions(warm) == (robust is not None)
        assert warm.final_error == pytest.approx(fresh.final_error, rel=1e-6), robust
        assert warm.rejected_edges == fresh.rejected_edges
    assert (false & touching).any() and warm.rejected_edges == remaining_false.tolist()


@pytest.mark.parametrize("group", [SE2, SE3, Sim3])
def test_graphs_with_nothing_to_optimise(group):
    """An empty graph, and graphs whose every node is held, end at once with every
    initialisation and robust mode (the empty one raised IndexError in the spanning tree and
    chordal's solve), also when one grows by a prior after a solve (IndexError in the growth of
    its empty sparsity pattern)."""
    held = PoseGraph(group)
    held.add_nodes([0, 1], group.identity((2,)))
    held.add_edge(0, 1, group.exp(np.full(group.dof, 0.1)), np.eye(group.dof))
    held.fix([0, 1])
    single = PoseGraph(group)
    single.add_node(4, group.identity())
    for graph in (PoseGraph(group), held, single):
        for init in ("auto", "file", "odometry", "spanning-tree", "chordal"):
            result = posegraph.optimize(graph.copy(), init=init)
            assert result.summary.termination == "nothing to optimise"
        for robust in ("gnc", "huber"):
            assert posegraph.optimize(graph.copy(), robust=robust).summary.converged
    result = posegraph.optimize(held)
    assert result.summary.final_error == pytest.approx(0.5 * 0.1**2 * group.dof)
    held.add_prior(0, group.exp(np.full(group.dof, 0.2)), np.eye(group.dof))
    grown = posegraph.optimize(held).summary
    assert "sparsity pattern (grown)" in grown.reused
    assert grown.final_error == pytest.approx(0.5 * (0.1**2 + 0.2**2) * group.dof)
    assert posegraph.marginals(PoseGraph(group), []).shape == (0, group.dof, group.dof)


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


def test_nodes_added_without_values_are_composed_from_their_edges():
    graph, _ = manhattan_world(num_poses=60, seed=81)
    fresh = PoseGraph(SE2)
    fresh.add_node(0, graph.values[0])
    fresh.add_nodes(graph.node_ids[1:])
    fresh.add_edges(
        graph.node_ids[graph.edges.i],
        graph.node_ids[graph.edges.j],
        graph.edges.measurements,
        graph.edges.information,
    )
    with pytest.raises(ValueError, match="no values"):
        posegraph.optimize(fresh.copy(), init="file")
    result = posegraph.optimize(fresh)
    assert result.summary.converged
    assert result.summary.final_error == pytest.approx(
        posegraph.optimize(graph).summary.final_error, rel=1e-6
    )


def test_warm_starts_reuse_the_solution_and_then_the_structure():
    full, _ = manhattan_world(num_poses=300, seed=82)
    summaries = [posegraph.optimize(graph).summary for graph in stream(full, 50)]
    assert summaries[0].initialization != "warm start"
    assert all(s.initialization == "warm start" for s in summaries[1:])
    assert all(s.reused and s.reused[0].startswith("previous solution") for s in summaries[1:])
    # Each step only appended nodes and edges: the pattern grows and the edges solved in the
    # previous call keep their linearisation (their nodes did not move since).
    assert all("sparsity pattern (grown)" in s.reused for s in summaries[1:])
    assert all(any(r.startswith("linearization of") for r in s.reused) for s in summaries[1:])
    scratch = posegraph.optimize(full.copy()).summary.final_error
    assert summaries[-1].final_error == pytest.approx(scratch, rel=1e-6)
    assert np.mean([s.num_iterations for s in summaries[1:]]) < np.mean(
        [summaries[0].num_iterations, 4]
    )


def test_new_poses_that_hang_off_the_solution_by_a_tree_are_composed_without_a_solve(
    monkeypatch,
):
    """A back end adds poses with their odometry alone: the solution, with each new pose composed
    from its neighbour, is already optimal (the new edges' residuals are zero and the rest is
    unchanged), so no linear system is built. A pose given a value is composed too. A solve
    from there and one from scratch agree, and so do the covariances."""
    graph, _ = manhattan_world(num_poses=120, seed=89)
    first = posegraph.optimize(graph)
    solution, last = graph.values, int(graph.node_ids[-1])
    step, back = SE2.from_xytheta([1.0, 0.1, 0.05]), SE2.from_xytheta([-0.8, 0.3, -0.2])
    graph.add_node(last + 1)
    graph.add_edge(last, last + 1, step, np.diag([50.0, 50.0, 200.0]))
    graph.add_node(last + 2, SE2.from_xytheta([5.0, 5.0, 1.0]))  # replaced: not the optimum
    graph.add_edge(last + 2, last + 1, back, np.array([[40.0, 5, 1], [5, 30, 2], [1, 2, 90]]))
    built = _count_normal_equations(monkeypatch)
    result = posegraph.optimize(graph)
    summary = result.summary
    assert built == [] and summary.termination == COMPOSED and summary.converged
    assert summary.num_iterations == 0 and summary.initialization == "warm start"
    assert graph.values[:120].same_as(solution)
    np.testing.assert_allclose(
        graph.matrices([last + 1, last + 2]),
        [(solution[-1] @ step).as_matrix(), (solution[-1] @ step @ back.inverse()).as_matrix()],
        atol=1e-12,
    )
    assert summary.final_error == pytest.approx(first.summary.final_error, rel=1e-12)
    again = posegraph.optimize(graph.copy(), init="file").summary  # a solve from there
    assert again.num_iterations <= 1 and again.num_variables == summary.num_variables
    assert summary.phase_times.keys() == again.phase_times.keys()
    assert again.final_error == pytest.approx(summary.final_error, rel=1e-12)
    scratch = posegraph.optimize(graph.copy(), init="chordal").summary.final_error
    assert summary.final_error <= scratch * (1 + 1e-9)
    np.testing.assert_allclose(
        posegraph.marginals(graph, [last + 2]),
        posegraph.marginals(graph.copy(), [last + 2]),
        rtol=1e-10,
    )
    restored = pickle.loads(pickle.dumps(graph))  # no cached system, the same solution
    restored.add_node(last + 3)
    restored.add_edge(last + 2, last + 3, step, np.eye(3))
    assert posegraph.optimize(restored).summary.termination == COMPOSED


def _add_odometry(graph: PoseGraph, information: np.ndarray | None = None) -> None:
    last = int(graph.node_ids[-1])
    graph.add_node(last + 1)
    graph.add_edge(
        last,
        last + 1,
        SE2.from_xytheta([1.0, 0.0, 0.1]),
        np.eye(3) if information is None else information,
    )


@pytest.mark.parametrize(
    "change",
    [
        "a loop",
        "an edge removed",
        "a prior",
        "a prior replaced",
        "a held pose",
        "a held pose released",
        "a pose alone",
        "a position-only edge",
        "moved values",
        "a solve stopped early",
        "a robust solve",
    ],
)
def test_a_solve_follows_where_a_tree_of_new_poses_is_not_all_that_changed(change):
    """The solution extends to the new poses only if nothing else changed: otherwise the warm
    start solves, and ends where a fresh solve does."""
    graph, _ = manhattan_world(num_poses=60, seed=90)
    if change == "a held pose released":
        graph.fix([30])  # at the generator's start value, off the optimum
    if change == "a prior replaced":
        graph.add_prior(0, graph.values[0], np.eye(3))
    posegraph.optimize(
        graph,
        options=posegraph.SolverOptions(max_iterations=1)
        if change == "a solve stopped early"
        else None,
        robust="huber" if change == "a robust solve" else None,
    )
    last = int(graph.node_ids[-1])
    if change == "an edge removed":  # and one more added: the new edges' count fits a tree
        graph.remove_edges([np.flatnonzero(robust_mask(graph, "loops"))[0]])
    _add_odometry(graph, np.diag([1.0, 1.0, 0.0]) if change == "a position-only edge" else None)
    if change in ("a loop", "an edge removed"):
        graph.add_edge(int(graph.node_ids[0]), last + 1, SE2.identity(), np.eye(3))
    elif change == "a prior":
        graph.add_prior(last + 1, SE2.from_xytheta([0.0, 0.0, 0.0]), np.eye(3))
    elif change == "a prior replaced":  # as a caller may, in place: the count stays
        moved = graph.priors.measurements.retract(np.full((1, 3), 0.5))
        graph.priors = dataclasses.replace(graph.priors, measurements=moved)
    elif change == "a held pose":
        graph.fix([last + 1])
    elif change == "a held pose released":
        graph.fix([30], fixed=False)
    elif change == "a pose alone":
        graph.add_node(last + 2, SE2.identity())
    elif change == "moved values":
        graph.set_values(graph.values.retract(np.full((graph.num_nodes, 3), 1e-3)))
    result = posegraph.optimize(graph)
    assert result.summary.termination != COMPOSED and result.summary.num_variables > 0
    scratch = posegraph.optimize(graph.copy(), init="chordal").summary.final_error
    assert result.summary.final_error == pytest.approx(scratch, rel=1e-6)


def test_streaming_with_false_loops_rejects_them_as_a_batch_call_does(tmp_path):
    """The incremental benchmark's robust mode (``--robust gnc --false-loops``): every call of
    the stream, warm-started, runs GNC, and the last one rejects exactly the false loops, which
    the benchmark finds among the streamed edges (they arrive in another order than the file's),
    as a call from scratch on the whole graph does."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    path = tmp_path / "manhattan.g2o"
    write_graph(graph, str(path))
    report = run(path, 50, robust="gnc", false_loops=0.1, seed=1)
    exactly_the_false_loops = "100.0% of the false loops and 0.00% of the true ones"
    assert f"reject {exactly_the_false_loops} (warm), {exactly_the_false_loops} (scratch)" in report
    assert "(3 optimisations)" in report


def _city_with_false_loops() -> tuple[PoseGraph, np.ndarray]:
    graph, _ = manhattan_world(num_poses=150, seed=93)
    return add_false_loops(graph, 0.1, seed=1)


def _drive_on(graph: PoseGraph, poses: int) -> None:
    """Append ``poses`` new poses without values, each by an odometry edge from the last."""
    last = int(graph.node_ids[-1])
    for k in range(last + 1, last + 1 + poses):
        graph.add_node(k)
        graph.add_edge(k - 1, k, SE2.from_xytheta([1.0, 0.1, 0.05]), np.eye(3) * 100.0)


def _stages(summary) -> set[str]:
    return {record.stage for record in summary.iterations}


def test_gnc_decisions_stand_when_only_trusted_odometry_was_added():
    """New poses that hang off the map by odometry alone leave the TLS problem over the solved
    poses as it was: the call keeps GNC's decisions and composes the new poses, and ends where
    GNC run again on the grown graph ends. Where the solved poses moved since, it solves over
    the decisions in least squares instead."""
    graph, false = _city_with_false_loops()
    first = posegraph.optimize(graph, robust="gnc")
    assert first.summary.rejected_edges == np.flatnonzero(false).tolist()
    _drive_on(graph, 5)
    grown = graph.copy()
    second = posegraph.optimize(graph, robust="gnc")
    assert second.summary.rejected_edges == first.summary.rejected_edges
    assert f"GNC's decisions ({false.sum()} rejected" in ", ".join(second.summary.reused)
    assert second.summary.termination == COMPOSED and second.summary.num_iterations == 0
    assert second.summary.robust == first.summary.robust
    assert second.summary.edges_under_kernel == first.summary.edges_under_kernel
    assert second.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-9)
    assert graph.values[:150].same_as(first.values)
    grown.solution = None
    again = posegraph.optimize(grown, robust="gnc")
    assert "least squares" in _stages(again.summary)
    assert again.summary.rejected_edges == second.summary.rejected_edges
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-6)
    graph.set_values(graph.values.retract(np.full((graph.num_nodes, 3), 1e-3)))
    _drive_on(graph, 5)
    third = posegraph.optimize(graph, robust="gnc")
    assert _stages(third.summary) == {"carried decisions"} and third.summary.converged
    assert third.summary.rejected_edges == first.summary.rejected_edges


def test_gnc_decisions_on_loops_and_priors_stand_when_only_odometry_was_added():
    """With ``robust_priors`` the robust problem holds the priors too, as edges after the
    between edges: the carried decisions keep the rejected fixes out as well."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    graph, false_loops = add_false_loops(graph, 0.1, seed=2)
    first = posegraph.optimize(graph, robust="gnc", robust_priors=True)
    assert first.summary.rejected_priors == np.flatnonzero(false_fixes).tolist()
    assert first.summary.rejected_edges == np.flatnonzero(false_loops).tolist()
    _drive_on(graph, 5)
    grown = graph.copy()
    grown.solution = None
    second = posegraph.optimize(graph, robust="gnc", robust_priors=True)
    again = posegraph.optimize(grown, robust="gnc", robust_priors=True)
    assert second.summary.termination == COMPOSED
    assert "least squares" in _stages(again.summary)
    assert second.summary.rejected_priors == again.summary.rejected_priors
    assert second.summary.rejected_edges == again.summary.rejected_edges
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-6)
    np.testing.assert_array_equal(graph.solution.prior_weights, (~false_fixes).astype(float))


def _add_loop(graph: PoseGraph) -> None:
    graph.add_edge(3, 140, SE2.from_xytheta([5.0, 0.0, 0.0]), np.eye(3) * 100.0)


def _add_second_odometry(graph: PoseGraph) -> None:
    graph.add_edge(10, 11, graph.edges.measurements[10], graph.edges.information[10])


def _add_prior(graph: PoseGraph) -> None:
    graph.add_prior(151, SE2.from_xytheta([0.0, 0.0, 0.0]), np.eye(3))


def test_gnc_decisions_stand_for_the_same_edge_class_given_as_indices_then_as_a_mask():
    """The robust class is compared edge by edge, however the caller gave it: loop closures
    given as indices, then (after new odometry) as a mask that leaves the new edges out."""
    graph, false = _city_with_false_loops()
    loops = robust_mask(graph, "loops")
    first = posegraph.optimize(graph, robust="gnc", robust_edges=np.flatnonzero(loops))
    assert first.summary.rejected_edges == np.flatnonzero(false).tolist()
    _drive_on(graph, 5)
    mask = np.append(loops, np.zeros(5, dtype=bool))
    second = posegraph.optimize(graph, robust="gnc", robust_edges=mask)
    assert _stages(second.summary) <= {"carried decisions"}
    assert second.summary.rejected_edges == first.summary.rejected_edges


def _one_true_loop_trusted(graph: PoseGraph) -> np.ndarray:
    mask = robust_mask(graph, "loops")
    mask[np.flatnonzero(mask)[0]] = False
    return mask


def _remove_first_loop(graph: PoseGraph) -> None:
    graph.remove_edges([np.flatnonzero(robust_mask(graph, "loops"))[0]])


def _remeasure_first_loop(graph: PoseGraph) -> None:
    """Replaces the first loop's measurement in place by one a little off, as a caller may."""
    first = np.flatnonzero(robust_mask(graph, "loops"))[0]
    nudged = graph.edges.measurements[first] @ SE2.from_xytheta([0.01, 0.0, 0.0])
    moved = graph.edges.measurements.set_at([first], nudged)
    graph.edges = dataclasses.replace(graph.edges, measurements=moved)


def _replace_first_prior(graph: PoseGraph) -> None:
    """Replaces the prior added before the first solve in place, as a caller may."""
    moved = graph.priors.measurements.set_at([0], SE2.from_xytheta([0.1, 0.0, 0.0]))
    graph.priors = dataclasses.replace(graph.priors, measurements=moved)


def _searched_from_decisions(summary) -> bool:
    return any(DECISIONS_AS_START in reuse for reuse in summary.reused)


@pytest.mark.parametrize(
    "change, robust, robust_edges, search",
    [
        (_add_loop, "gnc", "loops", "both"),
        (_add_second_odometry, "gnc", "loops", "decisions"),
        (_add_prior, "gnc", "loops", "decisions"),
        (lambda graph: graph.fix([151]), "gnc", "loops", "decisions"),
        (lambda graph: None, "gnc:3", "loops", "stages"),
        (lambda graph: None, "gnc", _one_true_loop_trusted, "stages"),
        (_remove_first_loop, "gnc", "loops", "decisions"),
        (_replace_first_prior, "gnc", "loops", "stages"),
        (_remeasure_first_loop, "gnc", "loops", "stages"),
    ],
    ids=[
        "a new false loop",
        "a cycle of trusted edges",
        "a prior",
        "a hold",
        "another width",
        "one old edge left out of the class",
        "an old loop removed",
        "a prior replaced",
        "an old loop remeasured",
    ],
)
def test_gnc_decides_again_when_what_was_added_could_change_its_decisions(
    change, robust, robust_edges, search
):
    """The decisions do not stand, and the call searches: from them alone where the graph only
    grew (or lost an old loop: ``PoseGraph.remove_edges`` carries them) under the same kernel
    and least squares over them settles as it is; from GNC's stages where they are not carried;
    from the better of both where least squares over them does not settle as it is (the new
    false loop, which they keep, misfits there). Either way the new false loop ends rejected."""
    graph, _ = _city_with_false_loops()
    graph.add_prior(0, SE2.identity(), np.eye(3))
    first = posegraph.optimize(graph, robust="gnc")
    _drive_on(graph, 5)
    change(graph)
    if callable(robust_edges):
        robust_edges = robust_edges(graph)
    summary = posegraph.optimize(graph, robust=robust, robust_edges=robust_edges).summary
    assert not any("nothing added since" in reuse for reuse in summary.reused)
    assert summary.termination != COMPOSED
    assert ("least squares" in _stages(summary)) == (search != "decisions")
    if search == "decisions":
        assert _searched_from_decisions(summary)
    if search == "stages":
        assert not _searched_from_decisions(summary) and "previous decisions" not in _stages(
            summary
        )
    if search == "both":
        assert {"previous decisions", "least squares"} <= _stages(summary)
        assert summary.rejected_edges == [*first.summary.rejected_edges, graph.num_edges - 1]


def test_gnc_searches_from_its_decisions_when_a_true_loop_arrives():
    """A true loop closed after the last GNC run: least squares over the run's decisions with
    the loop kept settles as it is, so the search starts there, and ends where GNC on the whole
    graph from scratch ends."""
    graph, false = _city_with_false_loops()
    true_loops = np.flatnonzero(robust_mask(graph, "loops") & ~false)
    held_out = graph.edges.subset([true_loops[-1]])
    ends = graph.node_ids[held_out.i[0]], graph.node_ids[held_out.j[0]]
    graph.remove_edges([true_loops[-1]])
    false = np.append(np.delete(false, true_loops[-1]), False)
    first = posegraph.optimize(graph, robust="gnc")
    graph.add_edge(*ends, held_out.measurements[0], held_out.information[0])
    scratch = graph.copy()
    scratch.solution = None
    second = posegraph.optimize(graph, robust="gnc")
    assert _searched_from_decisions(second.summary)
    assert "least squares" not in _stages(second.summary)
    assert "previous decisions" in _stages(second.summary)
    assert second.summary.rejected_edges == np.flatnonzero(false).tolist()
    assert np.abs(first.values.between(second.values).log()).max() > 1e-3  # the loop moved it
    again = posegraph.optimize(scratch, robust="gnc")
    assert again.summary.rejected_edges == second.summary.rejected_edges
    assert second.summary.final_error == pytest.approx(again.summary.final_error, rel=1e-9)
    # Both stop at Levenberg-Marquardt's tolerance, from different starts (poses ≈ 10 apart).
    np.testing.assert_allclose(second.values.as_matrix(), again.values.as_matrix(), atol=1e-5)


def test_gnc_streamed_keeps_decisions_that_beat_its_stages(shared_dataset):
    """MIT with 30% false loops (seed 0), streamed in steps of 10 poses, GNC at every step. At
    the step to 800 poses, least squares over the last decisions with the new loops misfits, and
    GNC's stages from there keep a false loop and reject three true ones; the decisions settled
    from that solution reach a lower TLS objective, and the search goes on from them. The stream
    ends with every false loop rejected and every true one kept, below the TLS objective of GNC
    on the whole graph from scratch (which rejects 3 of the 20 true loops)."""
    full = read_graph(shared_dataset("MIT.g2o")).graph
    full, false = add_false_loops(full, 0.3, seed=0)
    false = false[np.argsort(arrivals(full, 10)[1], kind="stable")]
    for graph in stream(full, 10):
        summary = posegraph.optimize(graph, robust="gnc").summary
    assert summary.rejected_edges == np.flatnonzero(false).tolist()
    scratch = graph.copy()
    scratch.solution = None
    assert summary.final_error < posegraph.optimize(scratch, robust="gnc").summary.final_error


@pytest.mark.parametrize("which", ["true", "false"])
def test_gnc_with_robust_priors_searches_on_when_a_fix_arrives(which):
    """With ``robust_priors`` a new fix (a prior) is a new measurement under the kernel: the
    call searches, from the last run's decisions where least squares over them settles, and
    ends with the rejections of GNC on the whole graph from scratch."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    last = np.flatnonzero(false_fixes == (which == "false"))[-1]
    held_out = graph.priors.subset([last])
    kept = np.arange(len(graph.priors)) != last
    graph.priors = graph.priors.subset(kept)
    posegraph.optimize(graph, robust="gnc", robust_priors=True)
    graph.add_prior(
        graph.node_ids[held_out.i[0]], held_out.measurements[0], held_out.information[0]
    )
    scratch = graph.copy()
    scratch.solution = None
    second = posegraph.optimize(graph, robust="gnc", robust_priors=True).summary
    again = posegraph.optimize(scratch, robust="gnc", robust_priors=True).summary
    false_now = np.append(false_fixes[kept], which == "false")
    assert second.rejected_priors == again.rejected_priors == np.flatnonzero(false_now).tolist()
    if which == "true":
        assert _searched_from_decisions(second) and "least squares" not in _stages(second)


def test_gnc_decides_again_when_the_priors_leave_the_kernel():
    graph, _ = city_with_fixes(0.3, seed=0)
    posegraph.optimize(graph, robust="gnc", robust_priors=True)
    _drive_on(graph, 5)
    summary = posegraph.optimize(graph, robust="gnc").summary
    assert "least squares" in _stages(summary) and not summary.rejected_priors


def test_gnc_decides_again_after_a_run_that_was_stopped():
    graph, _ = _city_with_false_loops()
    stopped = posegraph.optimize(graph, robust="gnc", callback=lambda record: True)
    assert stopped.summary.termination == STOPPED
    summary = posegraph.optimize(graph, robust="gnc").summary
    assert "least squares" in _stages(summary) and "carried decisions" not in _stages(summary)


def test_a_warm_start_restarts_when_new_loops_disagree_with_the_solution():
    """With rotations this noisy (σ = 0.4 rad per edge), the optimum of the first rings can sit
    in another basin than the optimum once later rings close their loops: solving on from it
    stalled at 419.6, where the graph's optimum is 322.4. The new loops then fail the χ² test
    against the previous solution, and the values restart from chordal relaxation."""
    full, truth = sphere(rings=8, poses_per_ring=16, rotation_sigma=0.4, translation_sigma=0.4)
    summaries = [posegraph.optimize(graph).summary for graph in stream(full, 16)]
    assert RESTART in [s.initialization for s in summaries[1:]]
    assert "warm start" in [s.initialization for s in summaries[1:]]
    from_truth = full.copy()
    from_truth.set_values(truth)
    best = posegraph.optimize(from_truth, init="file").summary.final_error
    assert summaries[-1].final_error == pytest.approx(best, rel=1e-6)


def test_only_new_measurements_that_disagree_restart_a_least_squares_warm_start():
    graph, _ = manhattan_world(num_poses=120, seed=87)
    posegraph.optimize(graph)
    loops = np.flatnonzero(np.abs(graph.edges.j - graph.edges.i) > 1)
    graph.remove_edges(loops[:3])  # the solution still suits the measurements that remain
    assert posegraph.optimize(graph).summary.initialization == "warm start"
    robust = graph.copy()
    for g in (graph, robust):  # a loop 30 m and 2 rad away from what the map says
        g.add_edge(0, 60, SE2.from_xytheta([30.0, 0.0, 2.0]), np.eye(3) * 100)
    assert posegraph.optimize(graph).summary.initialization == RESTART
    # A robust solve keeps its warm start: chordal relaxation would spread an outlier's pull.
    assert posegraph.optimize(robust, robust="gnc").summary.initialization == "warm start"


def test_the_restarts_chi2_test_counts_the_directions_a_measurement_weighs():
    """A prior 15 Mahalanobis units² from the solution is consistent as a full SE2 prior
    (χ²₃(0.999) = 16.3) but not as a position-only one (χ²₂(0.999) = 13.8): counted as 3
    degrees of freedom, the position-only prior kept its warm start."""
    initializations = []
    for information in (np.eye(3), np.diag([1.0, 1.0, 0.0])):
        graph, _ = manhattan_world(num_poses=120, seed=87)
        posegraph.optimize(graph)
        off = graph.values_of([60]) @ SE2.from_xytheta([np.sqrt(15.0), 0.0, 0.0])
        graph.add_prior(60, off, information)
        initializations.append(posegraph.optimize(graph).summary.initialization)
    assert initializations == ["warm start", RESTART]


def test_an_optimised_graph_and_its_result_pickle_and_warm_start_alike():
    """A back end checkpoints its graph, or hands it to another process, after optimising.
    The CHOLMOD handles of the solver cache cannot be pickled, so they are left out: the copy
    warm-starts from the same values to the same optimum, building its system anew."""
    graph, _ = manhattan_world(num_poses=120, seed=86)
    result = posegraph.optimize(graph)
    copies = [pickle.loads(pickle.dumps(graph)), copy.deepcopy(graph)]
    for restored in copies:
        assert restored.last_result is None and restored.optimized
        assert restored.values.same_as(graph.values)
    np.testing.assert_array_equal(
        pickle.loads(pickle.dumps(result)).values.as_matrix(), result.values.as_matrix()
    )
    assert copy.deepcopy(result).summary == result.summary
    summaries = []
    for g in [graph, *copies]:
        first, last = int(g.node_ids[0]), int(g.node_ids[-1])
        g.add_edge(first, last, g.values[0].between(g.values[-1]), np.eye(3))
        summaries.append(posegraph.optimize(g).summary)
    assert all(s.initialization == "warm start" for s in summaries)
    assert "sparsity pattern (grown)" in summaries[0].reused
    assert not any(r.startswith("sparsity") for s in summaries[1:] for r in s.reused)
    assert all(
        s.final_error == pytest.approx(summaries[0].final_error, rel=1e-9) for s in summaries
    )


def test_unchanged_structure_reuses_pattern_and_symbolic_factorization():
    graph = random_graph(SE2, 40, 20, seed=83, noise=0.1)
    first = posegraph.optimize(graph)
    graph.set_values(
        graph.values.retract(np.random.default_rng(84).normal(scale=0.05, size=(40, 3)))
    )
    second = posegraph.optimize(graph)
    assert (
        "sparsity pattern" in second.summary.reused
        and "symbolic factorization" in second.summary.reused
    )
    assert not any(r.startswith("linearization") for r in second.summary.reused)  # nodes moved
    assert second.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-6)
    again = posegraph.optimize(graph)  # nothing changed: the solution stands, with no solve
    assert again.summary.termination == COMPOSED and again.values.same_as(second.values)
    assert again.summary.final_error == second.summary.final_error
    graph.add_edge(
        graph.node_ids[0], graph.node_ids[30], graph.values[0].between(graph.values[30]), np.eye(3)
    )
    third = posegraph.optimize(graph)
    assert "sparsity pattern" not in third.summary.reused  # the structure changed
    assert "sparsity pattern (grown)" in third.summary.reused  # by an appended edge
    # The edges solved before keep their linearisation: their nodes have not moved since.
    assert f"linearization of {graph.num_edges - 1} edges" in third.summary.reused
    graph.remove_edges([graph.num_edges - 1])
    fourth = posegraph.optimize(graph)
    assert not any(r.startswith("sparsity pattern") for r in fourth.summary.reused)
    assert not any(r.startswith("linearization") for r in fourth.summary.reused)
    assert fourth.summary.final_error == pytest.approx(first.summary.final_error, rel=1e-6)


def test_irls_calls_reuse_the_last_system_and_linearisation_as_least_squares_calls_do():
    """An IRLS kernel's warm call keeps its normal equations and linearisation for the next:
    the weights are taken anew from the reused residuals, so it ends where a call that rebuilds
    everything (on a copy, which drops them) ends."""
    graph = random_graph(SE2, 40, 20, seed=83, noise=0.1)
    posegraph.optimize(graph, robust="cauchy")
    rebuilt = posegraph.optimize(graph.copy(), robust="cauchy")
    again = posegraph.optimize(graph, robust="cauchy")
    assert not any(r.startswith(("sparsity", "linearization")) for r in rebuilt.summary.reused)
    assert {"sparsity pattern", "symbolic factorization"} <= set(again.summary.reused)
    assert f"linearization of {graph.num_edges} edges" in again.summary.reused
    assert again.summary.final_error == pytest.approx(rebuilt.summary.final_error, rel=1e-12)
    _drive_on(graph, 3)
    grown = posegraph.optimize(graph, robust="cauchy")
    assert "sparsity pattern (grown)" in grown.summary.reused
    assert f"linearization of {graph.num_edges - 3} edges" in grown.summary.reused


def test_marginals_after_gnc_leave_the_rejected_loops_out():
    """A back end that rejects false loop closures must not have them shrink its covariances:
    after GNC they are those of the graph without the false loops. Before, every rejected loop
    counted with its full information."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    corrupted, false = add_false_loops(graph, 0.1, seed=1)
    result = posegraph.optimize(corrupted, robust="gnc")
    np.testing.assert_array_equal(result.summary.rejected_edges, np.flatnonzero(false))
    posegraph.optimize(graph)
    nodes = graph.node_ids[[40, 90, 149]]
    np.testing.assert_allclose(
        posegraph.marginals(corrupted, nodes), posegraph.marginals(graph, nodes), rtol=1e-5
    )
    # An edge added since the solution counts in full until the next solve weighs it.
    corrupted.add_edge(0, 149, graph.values[0].between(graph.values[149]), np.eye(3) * 1e4)
    graph.add_edge(0, 149, graph.values[0].between(graph.values[149]), np.eye(3) * 1e4)
    np.testing.assert_allclose(
        posegraph.marginals(corrupted, nodes, values=graph.values),
        posegraph.marginals(graph, nodes, values=graph.values),
        rtol=1e-9,
    )


def test_gnc_with_fixes_searches_from_its_decisions_after_a_fix_and_a_keyframe_go():
    """Under ``robust_priors`` the GNC problem holds the edges, then the priors: removing a
    false fix and culling a keyframe with a fix keeps the decisions on what remains, and the
    search from them rejects what GNC from scratch rejects."""
    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    posegraph.optimize(corrupted, robust="gnc", robust_priors=True)
    corrupted.remove_priors([np.flatnonzero(false_fixes)[0]])
    fixed_nodes = corrupted.node_ids[corrupted.priors.i]
    cull(corrupted, int(fixed_nodes[(fixed_nodes > 0) & (fixed_nodes < 299)][3]))
    edges, priors = corrupted.rejected()
    assert edges.sum() == false_loops.sum() and priors.sum() == false_fixes.sum() - 1
    scratch = corrupted.copy()
    scratch.solution = None
    warm = posegraph.optimize(corrupted, robust="gnc", robust_priors=True).summary
    fresh = posegraph.optimize(scratch, robust="gnc", robust_priors=True).summary
    assert _searched_from_decisions(warm) and not _searched_from_decisions(fresh)
    assert warm.rejected_edges == fresh.rejected_edges == np.flatnonzero(edges).tolist()
    assert warm.rejected_priors == fresh.rejected_priors == np.flatnonzero(priors).tolist()
    assert warm.final_error == pytest.approx(fresh.final_error, rel=1e-6)


def test_marginals_after_culling_still_leave_the_rejected_loops_out():
    """A keyframe culled after GNC: the weights stay with the edges that remain, so the
    covariances are still those of the inliers, at the same values; with every loop counted
    in full they would be smaller."""
    graph, _ = manhattan_world(num_poses=150, seed=93)
    corrupted, false = add_false_loops(graph, 0.1, seed=1)
    posegraph.optimize(corrupted, robust="gnc")
    cull(corrupted, 75)
    nodes = corrupted.node_ids[[40, 74, 148]]
    ours = posegraph.marginals(corrupted, nodes)
    inliers = corrupted.without_rejected()
    assert inliers.num_edges == corrupted.num_edges - np.count_nonzero(false) > 0
    np.testing.assert_allclose(ours, posegraph.marginals(inliers, nodes), rtol=1e-9)
    counted_in_full = corrupted.copy()
    counted_in_full.solution = None
    in_full = np.trace(posegraph.marginals(counted_in_full, nodes), axis1=1, axis2=2)
    assert np.all(in_full < 0.95 * np.trace(ours, axis1=1, axis2=2))


def test_without_rejected_keeps_what_a_robust_solve_kept():
    """After GNC, ``rejected`` marks exactly the false loops and the false fixes, and
    ``without_rejected`` holds the rest. GNC's last solve is least squares over its decisions,
    so least squares over the inliers stays at the robust solution, where the TLS cost is theirs
    plus ½c² for each rejected measurement (c = √χ²₃(0.999)). Measurements added since are not
    rejected; those that remain after a removal keep theirs (``Solution.without``), and a
    measurement changed in place makes its kind's rejections unknown."""
    from scipy.stats import chi2 as chi2_distribution

    graph, false_fixes = city_with_fixes(0.3, seed=0)
    corrupted, false_loops = add_false_loops(graph, 0.1, seed=0)
    robust = posegraph.optimize(corrupted, robust="gnc", robust_priors=True)
    edges, priors = corrupted.rejected()
    np.testing.assert_array_equal(edges, false_loops)
    np.testing.assert_array_equal(priors, false_fixes)
    inliers = corrupted.without_rejected()
    np.testing.assert_array_equal(inliers.edges.i, corrupted.edges.i[~false_loops])
    np.testing.assert_array_equal(inliers.edges.j, corrupted.edges.j[~false_loops])
    np.testing.assert_array_equal(inliers.priors.i, corrupted.priors.i[~false_fixes])
    assert not inliers.rejected()[0].any() and not inliers.rejected()[1].any()
    least_squares = posegraph.optimize(inliers, init="file")
    assert least_squares.summary.final_error == pytest.approx(
        least_squares.summary.initial_error, rel=1e-9
    )
    np.testing.assert_allclose(inliers.positions(), corrupted.positions(), atol=1e-6)
    width_squared = chi2_distribution.ppf(0.999, 3)
    rejected = false_loops.sum() + false_fixes.sum()
    assert robust.summary.final_error == pytest.approx(
        least_squares.summary.final_error + 0.5 * width_squared * rejected, rel=1e-9
    )
    corrupted.add_edge(0, 299, graph.values[0].between(graph.values[299]), np.eye(3))
    edges, priors = corrupted.rejected()
    np.testing.assert_array_equal(edges, np.append(false_loops, False))
    np.testing.assert_array_equal(priors, false_fixes)
    corrupted.remove_edges([0])
    corrupted.remove_priors([np.flatnonzero(false_fixes)[0]])
    edges, priors = corrupted.rejected()
    np.testing.assert_array_equal(edges, np.append(false_loops, False)[1:])
    np.testing.assert_array_equal(priors, np.delete(false_fixes, np.flatnonzero(false_fixes)[0]))
    assert edges.any() and priors.any()
    moved = corrupted.priors.measurements.retract(np.full((len(corrupted.priors), 3), 0.1))
    corrupted.priors = dataclasses.replace(corrupted.priors, measurements=moved)
    edges, priors = corrupted.rejected()
    assert edges.any() and not priors.any()
    posegraph.optimize(graph)
    assert not any(mask.any() for mask in graph.rejected())  # least squares rejects nothing


def _count_normal_equations(monkeypatch) -> list:
    """A list that grows by one whenever ``NormalEquations`` are built."""
    built, init = [], NormalEquations.__init__

    def counted(self, *args, **kwargs):
        built.append(1)
        init(self, *args, **kwargs)

    monkeypatch.setattr(NormalEquations, "__init__", counted)
    return built


def test_the_newest_poses_covariance_fills_the_last_solves_normal_equations(monkeypatch):
    """A back end reads its newest pose's covariance after each step: the normal equations of
    the step's solve (pattern and CHOLMOD's analysis) serve it, refilled at the optimum; after
    a structural change they are built anew. Either way the covariance is that of a graph
    never optimised here (a copy, which has no cached system)."""
    graph, _ = manhattan_world(num_poses=120, seed=88)
    posegraph.optimize(graph)
    newest = graph.node_ids[-1:]
    built = _count_normal_equations(monkeypatch)
    covariance = posegraph.marginals(graph, newest)
    assert built == []
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), newest), rtol=1e-10)
    graph.add_edge(int(graph.node_ids[0]), int(newest[0]), SE2.identity(), np.eye(3))
    built.clear()
    covariance = posegraph.marginals(graph, newest)
    assert built == [1]
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), newest), rtol=1e-10)


def test_the_covariance_at_the_solution_factorises_the_h_the_solve_assembled(monkeypatch):
    """At the solution of a least-squares solve, the covariance factorises the H that the
    solve assembled there, without linearising again; at other values, and after a robust
    solve (whose H holds IRLS weights), it linearises. The covariance is the same either way
    (a copy, which has no cached solve, computes it afresh)."""
    graph, _ = manhattan_world(num_poses=120, seed=88)
    posegraph.optimize(graph)
    nodes = graph.node_ids[[-1, 40]]
    linearised = []
    # The package's attribute posegraph.marginals is the function, so the module by its name.
    marginals_module = importlib.import_module("posegraph.marginals")
    fresh = marginals_module.factorized_information

    def counted(*args, **kwargs):
        linearised.append(1)
        return fresh(*args, **kwargs)

    monkeypatch.setattr(marginals_module, "factorized_information", counted)
    covariance = posegraph.marginals(graph, nodes)
    assert linearised == []
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), nodes), rtol=1e-10)
    moved = graph.values.retract(np.full((graph.num_nodes, 3), 0.01))
    linearised.clear()
    np.testing.assert_allclose(
        posegraph.marginals(graph, nodes, values=moved),
        posegraph.marginals(graph.copy(), nodes, values=moved),
        rtol=1e-10,
    )
    assert linearised == [1, 1]
    posegraph.optimize(graph, robust="huber")
    linearised.clear()
    covariance = posegraph.marginals(graph, nodes)
    assert linearised == [1]
    np.testing.assert_allclose(covariance, posegraph.marginals(graph.copy(), nodes), rtol=1e-10)


@pytest.mark.skipif("cholmod" not in sparse_cholesky.available_backends(), reason="no cvxopt")
def test_covariances_from_a_simplicial_ldlt_factor(monkeypatch):
    """With CHOLMOD set to simplicial factors (P A Pᵀ = L D Lᵀ), the solve's normal equations
    still give the covariance: D enters the solves."""
    from cvxopt import cholmod

    graph = random_graph(SE3, 30, 12, seed=89)
    monkeypatch.setitem(cholmod.options, "supernodal", 0)
    posegraph.optimize(graph)
    nodes = graph.node_ids[[4, 20]]
    reused = posegraph.marginals(graph, nodes)
    monkeypatch.delitem(cholmod.options, "supernodal")
    np.testing.assert_allclose(reused, posegraph.marginals(graph.copy(), nodes), rtol=1e-10)


@pytest.mark.parametrize("backend", sparse_cholesky.available_backends())
def test_covariances_are_symmetric_to_the_last_bit(backend):
    """Solves leave rounding asymmetry (SuperLU's did, by up to 1e-7 relative on graphs of
    information singular to rounding); a covariance handed out is symmetric exactly."""
    graph = random_graph(SE3, 30, 12, seed=86, noise=0.05)
    posegraph.optimize(graph)
    nodes = graph.node_ids[[2, 9, 17, 25]]
    blocks = posegraph.marginals(graph, nodes, linear_solver=backend)
    joint = posegraph.marginals(graph, nodes, joint=True, linear_solver=backend)
    np.testing.assert_array_equal(blocks, np.swapaxes(blocks, 1, 2))
    np.testing.assert_array_equal(joint, joint.T)


@pytest.mark.parametrize("backend", sparse_cholesky.available_backends())
def test_covariances_of_information_singular_to_working_precision_are_refused(backend):
    """A prior whose information has eigenvalues 1, 2 and 1e-14 (in turned axes): H factorises,
    its least pivot at rounding's scale, and its inverse would keep two digits. It is refused
    as a singular H is, naming the node. At 1e-10, the covariance is Ω⁻¹."""
    turn = SO3.exp(np.array([0.3, -0.5, 0.7])).rotation
    for least, refused in ((1e-14, True), (1e-10, False)):
        graph = PoseGraph(SE2)
        graph.add_node(7, SE2.identity())
        information = turn @ np.diag([1.0, 2.0, least]) @ turn.T
        graph.add_prior(7, SE2.identity(), 0.5 * (information + information.T))
        if refused:
            with pytest.raises(NotPositiveDefinite, match=r"\(node 7: 1 of its 3 directions\)"):
                posegraph.marginals(graph, [7], linear_solver=backend)
        else:
            covariance = posegraph.marginals(graph, [7], linear_solver=backend)[0]
            expected = np.linalg.inv(graph.priors.information[0])
            np.testing.assert_allclose(covariance, expected, rtol=1e-5, atol=1e-5 * 1e10)


@pytest.mark.parametrize(
    ("solved_columns", "coupled_columns"),
    [(SOLVED_COLUMNS, COUPLED_COLUMNS), (0, COUPLED_COLUMNS), (0, 0)],
    ids=["as set", "selected inversion", "joint by solves"],
)
def test_marginals_are_blocks_of_the_inverse_information(
    monkeypatch, solved_columns, coupled_columns
):
    """Against a dense inverse of H on a small graph (the library never forms one), by solves,
    by selected inversion, and with joint covariances too large to couple into the pattern."""
    monkeypatch.setattr(sparse_cholesky, "SOLVED_COLUMNS", solved_columns)
    monkeypatch.setattr(sparse_cholesky, "COUPLED_COLUMNS", coupled_columns)
    graph = random_graph(SE3, 12, 8, seed=85, noise=0.05, priors=0)
    posegraph.optimize(graph)
    held = graph.gauge_nodes()
    system = NormalEquations(graph, held, "scipy")
    data, _ = system.assemble(
        linearize_between(graph.values, graph.edges),
        graph.edges.information,
        linearize_priors(graph.values, graph.priors),
        graph.priors.information,
    )
    inverse = np.linalg.inv(system.matrix(data).toarray())
    nodes = graph.node_ids[[3, 7]]
    cov = posegraph.marginals(graph, nodes)
    for k, node in enumerate([3, 7]):
        block = slice(system.block_of[node] * 6, system.block_of[node] * 6 + 6)
        np.testing.assert_allclose(cov[k], inverse[block, block], rtol=1e-9, atol=1e-12)
    joint = posegraph.marginals(graph, nodes, joint=True)
    rows = np.r_[
        system.block_of[3] * 6 : system.block_of[3] * 6 + 6,
        system.block_of[7] * 6 : system.block_of[7] * 6 + 6,
    ]
    np.testing.assert_allclose(joint, inverse[np.ix_(rows, rows)], rtol=1e-9, atol=1e-12)
    assert np.all(posegraph.marginals(graph, graph.node_ids[held]) == 0)  # the gauge is exact
    assert posegraph.marginals(graph, []).shape == (0, 6, 6)
    assert posegraph.marginals(graph, [], joint=True).shape == (0, 0)
    every_node_held = graph.copy()
    every_node_held.fix(graph.node_ids)
    assert np.all(posegraph.marginals(every_node_held, graph.node_ids[:2]) == 0)
    for backend in ("scipy",):
        np.testing.assert_allclose(
            posegraph.marginals(graph, nodes, linear_solver=backend), cov, rtol=1e-8
        )
    np.testing.assert_allclose(posegraph.marginals(graph, nodes, values=graph.values), cov)
    with pytest.raises(ValueError, match=r"values are one per node \(12\), not \(2,\)"):
        posegraph.marginals(graph, nodes, values=graph.values[:2])
    graph.add_node(99)  # no value until the graph is optimised again
    graph.add_edge(int(graph.node_ids[0]), 99, SE3.identity(), np.eye(6))
    with pytest.raises(ValueError, match=r"nodes \[99\] have no values; optimise the graph first"):
        posegraph.marginals(graph, [99])


@pytest.mark.parametrize("group", [SE2, SE3, Sim3])
def test_relative_covariances_along_a_tree_compose_its_measurements_covariances(group):
    """Where one path of edges joins two nodes (a chain, at its optimum: every residual zero),
    the covariance of their relative pose is that of the path's composed measurements, by
    Eade §8.2 applied edge after edge (and §8.3 for the reverse pair), whichever node holds
    the gauge."""
    rng = np.random.default_rng(86)
    d = group.dof
    measurements = group.exp(0.4 * rng.normal(size=(5, d)))
    a = rng.normal(size=(5, d, d))
    information = a @ np.swapaxes(a, 1, 2) + d * np.eye(d)
    graph = PoseGraph(group)
    graph.add_nodes(range(6))
    graph.add_edges(range(5), range(1, 6), measurements, information)
    posegraph.optimize(graph)
    path, covariance = measurements[1], np.linalg.inv(information[1])
    for k in (2, 3):
        step = np.linalg.inv(information[k])
        covariance = compose_covariance(path, covariance, measurements[k], step)
        path = path @ measurements[k]
    for held in (0, 5):
        graph.fix(graph.node_ids, False)
        graph.fix([held])
        relative = posegraph.relative_covariances(graph, [1, 4, held, 2], [4, 1, 3, 2])
        np.testing.assert_allclose(relative[0], covariance, rtol=1e-8, atol=1e-12)
        reverse = inverse_covariance(path, covariance)
        np.testing.assert_allclose(relative[1], reverse, rtol=1e-8, atol=1e-12)
        # From a held node, the marginal; a node against itself, none.
        np.testing.assert_allclose(relative[2], posegraph.marginals(graph, [3])[0], rtol=1e-8)
        np.testing.assert_allclose(relative[3], 0.0, atol=1e-12 * np.abs(covariance).max())


def test_relative_covariances_do_not_depend_on_the_gauge_where_marginals_do():
    """Held at another node, a Manhattan world's poses have other covariances, and their
    relative poses the same ones (1e-9), by solves and by selected inversion."""
    graph, _ = manhattan_world(200, seed=87)
    posegraph.optimize(graph)
    regauged = graph.copy()
    regauged.fix([0], False)
    regauged.fix([120])
    rng = np.random.default_rng(87)
    for count in (3, 40):  # 18 columns by solves; 240 by selected inversion
        i, j = rng.choice(graph.node_ids, (2, count))
        ours, theirs = (posegraph.relative_covariances(g, i, j) for g in (graph, regauged))
        np.testing.assert_allclose(theirs, ours, rtol=1e-9, atol=1e-12 * np.abs(ours).max())
        marginal = posegraph.marginals(graph, j)
        assert not np.allclose(posegraph.marginals(regauged, j), marginal, rtol=1e-3)


def test_relative_covariances_need_a_measured_relative_pose():
    """Two maps apart: their nodes' relative pose is refused, unless a hold or a prior sets
    each map in the world frame; pairs of unequal counts are refused."""
    first, second = (random_graph(SE2, 6, 2, seed=s) for s in (88, 89))
    graph = union(first, second, id_offset=1000)
    posegraph.optimize(graph)
    a, b = int(first.node_ids[2]), int(second.node_ids[3]) + 1000
    assert posegraph.relative_covariances(graph, [a], [int(first.node_ids[4])]).shape == (1, 3, 3)
    message = rf"nodes {a} and {b} are in different connected components, not both set"
    with pytest.raises(ValueError, match=message):
        posegraph.relative_covariances(graph, [a], [b])
    graph.fix([int(first.node_ids[0])])
    with pytest.raises(ValueError, match=message):
        posegraph.relative_covariances(graph, [a], [b])
    graph.add_prior(b, graph.values_of([b])[0], np.eye(3))
    posegraph.optimize(graph)
    apart = posegraph.relative_covariances(graph, [a], [b])[0]
    # One map held by a node, the other by a prior: the poses are independent (Eade §8.2).
    x_a, x_b = graph.values_of([a]), graph.values_of([b])
    marginal = posegraph.marginals(graph, [a, b])
    expected = compose_covariance(
        x_a.inverse()[0], inverse_covariance(x_a[0], marginal[0]), x_b[0], marginal[1]
    )
    np.testing.assert_allclose(apart, expected, rtol=1e-9)
    with pytest.raises(ValueError, match="as many i as j ids, not 1 and 2"):
        posegraph.relative_covariances(graph, [a], [a, b])
    assert posegraph.relative_covariances(graph, [], []).shape == (0, 3, 3)
