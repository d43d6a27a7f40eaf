"""Random sequences of what a SLAM back end does to one graph (add nodes with and without
values, edges, priors; hold and release nodes; remove edges, priors and nodes; optimise, by
least squares or robustly; read covariances, also of relative poses), drawn by hypothesis:
every call either works or is refused with a ValueError, and each least-squares call that
warm-starts from the last ends no higher than a deep copy of the ``Smoother`` (the solution
without the solver's cache), which rebuilds everything (a sequence fuzzer found an IndexError in the growth of an all-held graph's
sparsity pattern this way). A call that composed new nodes without a solve (``COMPOSED``)
ends no higher than a solve from its values either."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import posegraph
from posegraph.graph import PoseGraph
from posegraph.lie import SE2, SE3, Sim3
from posegraph.smoother import COMPOSED

hypothesis = pytest.importorskip("hypothesis")
st = hypothesis.strategies

WARM_TOLERANCE = 1e-4
"""Relative excess of a warm start's final error over a fresh solve's that fails the test:
both stop at LM's tolerance, not at the exact optimum."""

node = st.tuples(st.just("node"), st.booleans())
edge = st.tuples(st.just("edge"), st.floats(0, 1), st.floats(0, 1), st.sampled_from([0.01, 0.5]))
prior = st.tuples(st.just("prior"), st.floats(0, 1))
hold = st.tuples(st.just("hold"), st.floats(0, 1), st.booleans())
remove = st.tuples(st.just("remove"), st.floats(0, 1))
unprior = st.tuples(st.just("unprior"), st.floats(0, 1))
cull = st.tuples(st.just("cull"), st.floats(0, 1))
solve = st.tuples(st.just("optimize"), st.sampled_from([None, None, "huber", "gnc"]))
covariances = st.tuples(st.just("marginals"), st.booleans())
steps = st.lists(
    st.one_of(
        node, node, edge, edge, prior, hold, remove, unprior, cull, solve, solve, covariances
    ),
    min_size=1,
    max_size=14,
)


def _pick(graph: PoseGraph, fraction: float) -> int:
    return int(graph.node_ids[min(int(fraction * graph.num_nodes), graph.num_nodes - 1)])


def _apply(smoother: posegraph.Smoother, step: tuple, rng: np.random.Generator) -> None:
    """One step; a step that makes no sense for the graph as it is does nothing."""
    graph = smoother.graph
    group, d = graph.group, graph.group.dof
    kind = step[0]
    if kind == "node":
        value = group.exp(0.3 * rng.normal(size=d)) if step[1] else None
        graph.add_node(int(graph.node_ids.max(initial=-1)) + 1, value)
    elif kind == "edge" and graph.num_nodes >= 2:
        i, j = _pick(graph, step[1]), _pick(graph, step[2])
        if i != j:
            measured = group.exp(step[3] * rng.normal(size=d))
            graph.add_edge(i, j, measured, np.eye(d) * rng.uniform(1, 100))
    elif kind == "prior" and graph.num_nodes:
        graph.add_prior(_pick(graph, step[1]), group.exp(0.1 * rng.normal(size=d)), np.eye(d))
    elif kind == "hold" and graph.num_nodes:
        graph.fix([_pick(graph, step[1])], step[2])
    elif kind == "remove" and graph.num_edges:
        smoother.remove_edges([min(int(step[1] * graph.num_edges), graph.num_edges - 1)])
    elif kind == "unprior" and len(graph.priors):
        smoother.remove_priors([min(int(step[1] * len(graph.priors)), len(graph.priors) - 1)])
    elif kind == "cull" and graph.num_nodes:
        smoother.remove_nodes([_pick(graph, step[1])])
    elif kind == "optimize":
        fresh = copy.deepcopy(smoother) if step[1] is None else None  # before the warm call
        warm = smoother.optimize(robust=step[1]).summary
        if fresh is not None:
            scratch = fresh.optimize().summary
            limit = scratch.final_error * (1 + WARM_TOLERANCE) + 1e-9
            assert warm.final_error <= limit, (warm.initialization, scratch.final_error)
        if fresh is not None and warm.termination == COMPOSED:
            again = posegraph.optimize(graph.copy(), init="file").summary
            assert warm.final_error <= again.final_error * (1 + WARM_TOLERANCE) + 1e-9
    elif kind == "marginals" and graph.num_nodes and smoother.optimized:
        covariance = posegraph.marginals(smoother, graph.node_ids[:3], joint=step[1])
        assert np.isfinite(covariance).all()
        ends = graph.node_ids[[0, -1]]  # refused (ValueError) where nothing relates them
        assert np.isfinite(posegraph.relative_covariances(smoother, ends[:1], ends[1:])).all()


@pytest.mark.parametrize("group", [SE2, SE3, Sim3], ids=lambda g: g.__name__)
@hypothesis.settings(max_examples=300, deadline=None, derandomize=True, database=None)
@hypothesis.given(sequence=steps)
def test_edit_sequences_work_or_are_refused_and_warm_starts_match_fresh_solves(group, sequence):
    smoother = posegraph.Smoother(PoseGraph(group))
    rng = np.random.default_rng(len(sequence))
    for step in sequence:
        try:
            _apply(smoother, step, rng)
        except ValueError:  # refused with its reason: no values, nothing measures a node, …
            continue
