"""Initial values: chordal relaxation, spanning trees, the choice, and components placed on their
priors."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from posegraph_datasets.generators import manhattan_world, sphere

import posegraph
from posegraph.graph import PoseGraph
from posegraph.init.choice import choose, initialize
from posegraph.init.chordal import chordal_values
from posegraph.lie import SE2, SE3, Sim3

from ..conftest import (
    SCALE_STEP,
    gnss_track,
    random_graph,
    sim3_scale_chain,
    union,
)


def _noise_free(graph: PoseGraph, truth) -> PoseGraph:
    exact = graph.copy()
    exact.edges = graph.edges.__class__(
        graph.edges.i,
        graph.edges.j,
        truth[graph.edges.i].between(truth[graph.edges.j]),
        graph.edges.information,
    )
    return exact


@pytest.mark.parametrize("generate", [manhattan_world, sphere], ids=["SE2", "SE3"])
def test_chordal_recovers_noise_free_poses_exactly(generate):
    graph, truth = generate(seed=4)
    exact = _noise_free(graph, truth)
    exact.set_values(graph.values.set_at(0, truth[0]))  # the held node at its true value
    values = chordal_values(exact)
    np.testing.assert_allclose(values.as_matrix(), truth.as_matrix(), atol=1e-8)


@pytest.mark.parametrize("group", [SE3, Sim3], ids=lambda g: g.__name__)
def test_chordal_survives_information_of_extreme_range(group):
    """One translation weight of 1e20 beside 100s, a range beyond double precision for normal
    equations (the doctor flags such matrices): H is not numerically positive definite, and
    chordal's solve takes the smallest ridge that factorises instead of failing."""
    truth = group.exp(np.random.default_rng(1).normal(scale=0.3, size=(6, group.dof)))
    graph = PoseGraph(group)
    graph.add_nodes(np.arange(6), truth)
    information = np.broadcast_to(100.0 * np.eye(group.dof), (6, group.dof, group.dof)).copy()
    information[2, 2, 2], information[2, 0, 1], information[2, 1, 0] = 1e20, 2.0, 2.0
    following = (np.arange(6) + 1) % 6
    graph.add_edges(np.arange(6), following, truth.between(truth[following]), information)
    assert np.isfinite(chordal_values(graph).as_matrix()).all()


def test_chordal_whose_system_no_ridge_factorises_is_refused_with_its_reason():
    """A weight of 1e200 coupled to one of 100 by 1e120, on an edge whose translation is 1e100
    (a damaged file's numbers): chordal's translation system cannot be factorised with any
    ridge. ``optimize`` refuses it as a ValueError that says why and what to use instead,
    rather than failing inside the sparse Cholesky; the odometry start still runs."""
    graph = PoseGraph(SE2)
    graph.add_nodes([0, 1, 2], SE2.from_xytheta(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]])))
    plain = np.diag([100.0, 100.0, 1000.0])
    extreme = np.array([[1e200, 1e120, 0], [1e120, 100, 0], [0, 0, 1000]])
    steps = np.array([[1, 0, 0], [1, 0, 0], [-2, 1e100, 0]])
    graph.add_edges([0, 1, 2], [1, 2, 0], SE2.from_xytheta(steps), [plain, extreme, plain])
    message = (
        "the chordal initialisation's linear system is not numerically positive definite, even"
        " with a ridge of 1e-06 diag(H): the information's range (entries up to 1e+200) is"
        " beyond double precision; the odometry initialisation composes the measurements instead"
    )
    with pytest.raises(ValueError, match=re.escape(message)):
        posegraph.optimize(graph.copy())
    assert posegraph.optimize(graph, init="odometry").summary.initialization == "odometry"


@pytest.mark.parametrize("method", ["odometry", "spanning-tree", "chordal"])
@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_initialisers_accept_full_information_and_several_components(group, method):
    """Each component keeps its gauge node where the graph has it: the tree initialisers
    started every component at the identity, so that optimising a map given away from the
    origin (or a second session's component) moved it there."""
    a = random_graph(group, 15, 8, seed=61, noise=0.02)
    graph = union(a, random_graph(group, 7, 0, seed=62, noise=0.02), 500)
    graph.add_nodes([9999], group.identity((1,)))  # an isolated node
    graph.add_edges(
        [a.node_ids[3]], [9999], a.edges.measurements[:1], a.edges.information[:1]
    )  # degree 1
    assert np.abs(graph.edges.information - np.swapaxes(graph.edges.information, 1, 2)).max() == 0
    assert (np.abs(graph.edges.information[:, 0, 1]) > 0).all()  # full, non-diagonal
    values = initialize(graph, method)
    assert np.isfinite(values.as_matrix()).all()
    held = graph.gauge_nodes()
    assert np.abs(graph.values[held].log()).min() > 0.1  # the roots are away from the origin
    np.testing.assert_array_equal(values[held].as_matrix(), graph.values[held].as_matrix())
    graph.set_values(values)
    result = posegraph.optimize(graph, init="file")
    assert result.summary.converged


@pytest.mark.parametrize("method", ["odometry", "spanning-tree", "chordal"])
def test_an_initialisation_beyond_double_precision_is_refused_naming_the_nodes(method):
    """``sim3_scale_chain`` composes to e^800 at node 8 and e^1000 at node 10 (the loop 1 → 0
    agrees with the chain): no double holds them. Chordal relaxation composes Sim3 translations
    along the tree as the others do, so it names the same nodes (solving for every translation
    at once, it lost all but node 0's)."""
    graph = sim3_scale_chain(with_values=False)
    graph.add_edge(1, 0, SCALE_STEP.inverse(), np.eye(7))
    message = (
        rf"the {method} initialisation composes the measurements to values beyond double"
        r" precision at nodes 8, 9, 10: a translation or scale too large to hold"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=message):
            initialize(graph, method)
        with pytest.raises(ValueError, match=message):
            posegraph.optimize(graph, init=method)
    assert not graph.initialized.any()  # nothing was set


def test_auto_picks_chordal_for_loops_and_odometry_for_trees():
    loopy = random_graph(SE3, 10, 5, seed=63)
    tree = random_graph(SE3, 10, 0, seed=64)
    assert choose(loopy) == "chordal" and choose(tree) == "odometry"
    assert posegraph.optimize(loopy).summary.initialization == "chordal"
    assert posegraph.optimize(tree).summary.initialization == "odometry"


@pytest.mark.parametrize("heading", [0.5, 1.5, 3.0])
@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_a_gnss_track_far_from_the_origin_reaches_its_optimum(group, heading):
    """Each initialiser started the track at the origin facing 0 (or, for chordal, at the first
    fix facing its identity rotation), and Levenberg-Marquardt ended at errors up to 7e13 after
    100 iterations. Moved onto the fixes, every initialiser and the robust mode reach the optimum
    found from the true poses."""
    graph, truth = gnss_track(group, heading, seed=66)
    from_truth = graph.copy()
    from_truth.set_values(truth)
    best = posegraph.optimize(from_truth, init="file").summary.final_error
    for init in ("auto", "odometry", "spanning-tree", "chordal"):
        summary = posegraph.optimize(graph.copy(), init=init).summary
        assert summary.final_error == pytest.approx(best, rel=1e-6), init
    assert posegraph.optimize(graph.copy(), robust="gnc").summary.final_error == pytest.approx(
        best, rel=1e-6
    )
    # A back end's second session: its own component, added to an optimised graph.
    first, second = graph.subgraph(np.arange(200) < 100), graph.subgraph(np.arange(200) >= 100)
    smoother = posegraph.Smoother(first)
    smoother.optimize()
    ids = second.node_ids
    first.add_nodes(ids)
    first.add_edges(
        ids[second.edges.i],
        ids[second.edges.j],
        second.edges.measurements,
        second.edges.information,
    )
    first.add_priors(ids[second.priors.i], second.priors.measurements, second.priors.information)
    two_sessions = first.copy()
    two_sessions.set_values(truth)
    best = posegraph.optimize(two_sessions, init="file").summary.final_error
    summary = smoother.optimize().summary
    assert summary.initialization == "warm start"
    assert summary.final_error == pytest.approx(best, rel=1e-6)


def test_a_component_with_one_full_prior_is_placed_on_it():
    graph = random_graph(SE3, 12, 4, seed=67, noise=0.02, priors=0)
    measurement = SE3.exp(np.array([100.0, -50.0, 3.0, 0.3, -0.2, 2.5]))
    graph.add_prior(graph.node_ids[5], measurement, np.eye(6))
    for init in ("odometry", "chordal"):
        values = initialize(graph, init)
        np.testing.assert_allclose(values[5].as_matrix(), measurement.as_matrix(), atol=1e-9)


@pytest.mark.parametrize("group", [SE2, SE3, Sim3], ids=lambda g: g.__name__)
def test_components_are_placed_on_their_own_priors_all_at_once(group):
    """Components set by position fixes at four points (two such), by one full prior, by one
    position-only prior, by two equal priors on rotation only that disagree (the first
    counts) and by none, in one graph: each lands where it lands alone."""
    rng = np.random.default_rng(69)
    d, dof = group.point_dim, group.dof
    position_only = np.diag(np.where(np.arange(dof) < d, 1.0, 0.0))
    setups = [
        (np.arange(4) * 2, position_only),
        (np.arange(4) + 3, 3.0 * position_only),
        ([3], np.eye(dof)),
        ([5], position_only),
        ([1, 4], np.eye(dof) - position_only),
        ([], np.eye(dof)),
    ]
    graph = PoseGraph(group)
    for c, (fixed_at, information) in enumerate(setups):
        part = random_graph(group, 8, 2, seed=70 + c, noise=0.02)
        ids = part.node_ids + 1000 * c
        graph.add_nodes(ids, part.values)
        graph.add_edges(
            ids[part.edges.i], ids[part.edges.j], part.edges.measurements, part.edges.information
        )
        if len(fixed_at):
            moved = group.exp(5.0 * rng.normal(size=(len(fixed_at), dof))) @ part.values[fixed_at]
            graph.add_priors(ids[fixed_at], moved, information)
    labels = graph.components()
    first_of_equals = graph.priors.i[-2]
    for method in ("odometry", "chordal"):
        together = initialize(graph, method)
        for c in range(len(setups)):
            alone = initialize(graph.subgraph(labels == c), method)
            np.testing.assert_allclose(
                together[labels == c].as_matrix(), alone.as_matrix(), atol=1e-9
            )
        np.testing.assert_allclose(
            together[first_of_equals].as_matrix(), graph.priors.measurements[-2].as_matrix()
        )


def test_spanning_tree_prefers_informative_edges():
    """With a weak odometry edge, the spanning tree goes around it through a strong loop."""
    graph = PoseGraph(SE2)
    truth = SE2.exp(np.random.default_rng(65).normal(size=(4, 3)))
    graph.add_nodes(np.arange(4), SE2.identity((4,)))
    i, j = np.array([0, 1, 2, 0]), np.array([1, 2, 3, 3])
    wrong = truth[1].between(truth[2]).retract(np.array([5.0, 5.0, 1.0]))
    measurements = truth[i].between(truth[j]).set_at(1, wrong)
    information = np.stack([np.eye(3) * w for w in (100.0, 1e-3, 100.0, 100.0)])
    graph.add_edges(i, j, measurements, information)
    values = initialize(graph, "spanning-tree")
    aligned = truth[0].inverse() @ truth
    np.testing.assert_allclose(values.as_matrix(), aligned.as_matrix(), atol=1e-9)
    assert not np.allclose(
        initialize(graph, "odometry").as_matrix(), aligned.as_matrix(), atol=1e-3
    )


@pytest.mark.parametrize("method", ["odometry", "spanning-tree"])
def test_a_tree_start_composes_the_measurements_of_a_chain_beyond_46341_poses(method):
    """The tree's parents come from scipy as int32; an edge's key parent · n + child overflows
    it from n² > 2³¹ on, and then composed the wrong edges (a 50,000-pose chain started at
    error 548 and ended unconverged after 100 iterations)."""
    n = 50_000
    graph = PoseGraph(SE2)
    graph.add_node(0, SE2.identity())
    graph.add_nodes(np.arange(1, n))
    steps = SE2.exp(np.random.default_rng(68).normal(scale=0.1, size=(n - 1, 3)))
    graph.add_edges(np.arange(n - 1), np.arange(1, n), steps, np.eye(3))
    values = initialize(graph, method)
    np.testing.assert_allclose(values[1:].as_matrix(), (values[:-1] @ steps).as_matrix(), atol=1e-9)
