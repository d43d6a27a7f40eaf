"""The fixed-pattern normal equations against a dense assembly, for every backend."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
from posegraph_datasets.generators import docked, sphere

import posegraph.problem.cholesky
from posegraph.problem.backends import available_backends, make_cholesky
from posegraph.problem.cholesky import (
    AUTO,
    SIMPLICIAL,
    SUPERNODAL,
    NotPositiveDefinite,
    builds_transposed,
    ones_at,
)
from posegraph.problem.factors import linearize_between, linearize_priors
from posegraph.problem.linear import NormalEquations

from ..conftest import POSE_GROUPS, random_graph


def _dense_system(graph, held):
    """H and g by stacking every edge's Jacobian rows into one dense J (no pattern involved)."""
    d, n = graph.group.dof, graph.num_nodes
    rows, residuals, weights = [], [], []
    lin = linearize_between(graph.values, graph.edges)
    for k in range(graph.num_edges):
        row = np.zeros((d, n * d))
        row[:, graph.edges.i[k] * d : (graph.edges.i[k] + 1) * d] = lin.jac_i[k]
        row[:, graph.edges.j[k] * d : (graph.edges.j[k] + 1) * d] += lin.jac_j[k]
        rows.append(row)
        residuals.append(lin.residuals[k])
        weights.append(graph.edges.information[k])
    prior_lin = linearize_priors(graph.values, graph.priors)
    for k in range(len(graph.priors)):
        row = np.zeros((d, n * d))
        row[:, graph.priors.i[k] * d : (graph.priors.i[k] + 1) * d] = prior_lin.jac_j[k]
        rows.append(row)
        residuals.append(prior_lin.residuals[k])
        weights.append(graph.priors.information[k])
    free = np.setdiff1d(np.arange(n), held)
    columns = (free[:, None] * d + np.arange(d)).ravel()
    hessian = np.zeros((columns.size, columns.size))
    gradient = np.zeros(columns.size)
    for row, r, omega in zip(rows, residuals, weights, strict=True):
        jac = row[:, columns]
        hessian += jac.T @ omega @ jac
        gradient += jac.T @ omega @ r
    return hessian, gradient


def _assert_matches_dense(system, graph, held, damping: float) -> np.ndarray:
    """H and g assembled by ``system`` equal the dense ones, and so does the solution of
    (H + damping·I) δ = −g, which is returned."""
    lin = linearize_between(graph.values, graph.edges)
    prior_lin = linearize_priors(graph.values, graph.priors)
    terms = (lin, graph.edges.information, prior_lin, graph.priors.information)
    data, gradient = system.normal_matrix(*terms), system.gradient(*terms)
    expected_h, expected_g = _dense_system(graph, held)
    np.testing.assert_allclose(system.matrix(data).toarray(), expected_h, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(gradient, expected_g, rtol=1e-12, atol=1e-9)
    system.factorize(data, np.full(system.size, damping))
    step = system.solve(-gradient)
    expected_step = np.linalg.solve(expected_h + damping * np.eye(system.size), -expected_g)
    np.testing.assert_allclose(step, expected_step, rtol=1e-8)
    return step


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("group", POSE_GROUPS, ids=lambda g: g.__name__)
def test_assembly_and_solve_match_dense(group, backend):
    graph = random_graph(group, 12, 8, seed=5, priors=2)
    held = np.array([0, 5])
    system = NormalEquations(graph, held, backend)
    step = _assert_matches_dense(system, graph, held, 0.5)
    assert system.scatter(step)[held].sum() == 0


@pytest.mark.parametrize("backend", available_backends())
def test_indefinite_matrix_is_reported(backend):
    graph = random_graph(POSE_GROUPS[0], 6, 2, seed=6)
    system = NormalEquations(graph, graph.gauge_nodes(), backend)
    lin = linearize_between(graph.values, graph.edges)
    prior_lin = linearize_priors(graph.values, graph.priors)
    data = system.normal_matrix(lin, graph.edges.information, prior_lin, graph.priors.information)
    with pytest.raises(NotPositiveDefinite):
        system.factorize(data, np.full(system.size, -1e9))


@pytest.mark.parametrize("mode", [SIMPLICIAL, AUTO, SUPERNODAL])
def test_cholmod_refuses_an_indefinite_matrix_whatever_its_factor(mode, monkeypatch):
    """LDLᵀ without pivoting factorises [[1, 2], [2, 1]] (D = 1, −3); the factoriser refuses it
    as LLᵀ does, and factorises the definite [[2, 1], [1, 2]]."""
    if "cholmod" not in available_backends():
        pytest.skip("cvxopt is not installed here")
    monkeypatch.setattr(posegraph.problem.cholesky, "AUTO", mode)
    indptr, indices = np.array([0, 2, 4]), np.array([0, 1, 0, 1])
    cholesky = make_cholesky(indices, indptr, 2, "cholmod")
    with pytest.raises(NotPositiveDefinite):
        cholesky.factorize(np.array([1.0, 2.0, 2.0, 1.0]))
    cholesky.factorize(np.array([2.0, 1.0, 1.0, 2.0]))
    np.testing.assert_allclose(cholesky.solve(np.array([3.0, 3.0])), [1.0, 1.0])
    np.testing.assert_allclose(np.sort(cholesky.pivots()), [1.5, 2.0])


@pytest.mark.parametrize(
    "backend, factor",
    [("cholmod", "simplicial"), ("cholmod", "supernodal"), ("scipy", "LU")],
)
def test_pivots_are_each_columns_schur_complement_where_it_is_eliminated(
    backend, factor, monkeypatch
):
    """A random sparse SPD matrix whose diagonal spans 1e-6 to 1e6: the pivots' product is
    det A, and each pivot lies between 1/(A⁻¹)ⱼⱼ (column j eliminated last) and Aⱼⱼ (first),
    which a pivot given to the wrong column would miss. CHOLMOD's factor is supernodal (LLᵀ)
    or simplicial (LDLᵀ), as its analysis is told."""
    if backend not in available_backends():
        pytest.skip(f"{backend} is not installed here")
    mode = {"simplicial": SIMPLICIAL, "supernodal": SUPERNODAL}.get(factor)
    if mode is not None:
        monkeypatch.setattr(posegraph.problem.cholesky, "AUTO", mode)
    size = 300
    rng = np.random.default_rng(76)
    root = scipy.sparse.random(size, size, density=0.01, random_state=77) + scipy.sparse.eye(size)
    scale = scipy.sparse.diags(10 ** rng.uniform(-3, 3, size))
    matrix = (scale @ root @ root.T @ scale).tocsc()
    matrix.sort_indices()
    cholesky = make_cholesky(matrix.indices, matrix.indptr, size, backend)
    cholesky.factorize(matrix.data)
    pivots = cholesky.pivots()
    if mode is not None:
        assert cholesky._is_supernodal() == (mode == SUPERNODAL)
    dense = matrix.toarray()
    assert np.log(pivots).sum() == pytest.approx(np.linalg.slogdet(dense)[1], abs=1e-9)
    lowest, highest = 1.0 / np.diag(np.linalg.inv(dense)), np.diag(dense)
    assert np.all(pivots >= lowest * (1 - 1e-9)) and np.all(pivots <= highest * (1 + 1e-9))


@pytest.mark.parametrize("long_columns", [0, 3], ids=["short", "long"])
def test_cvxopt_pattern_holds_each_entry_once_in_column_order(long_columns):
    """Columns of thousands of entries (a node many edges reach) are built transposed and
    added; either way the matrix holds ones exactly at the entries, rows sorted per column."""
    if "cholmod" not in available_backends():
        pytest.skip("cvxopt is not installed here")
    rng = np.random.default_rng(78)
    size = 3000
    pattern = scipy.sparse.random(size, size, density=0.002, random_state=79).tolil()
    pattern[:, rng.choice(size, long_columns, replace=False)] = 1.0
    matrix = pattern.tocsc()
    matrix.sort_indices()
    counts = np.diff(matrix.indptr)
    assert np.count_nonzero(builds_transposed(counts)) == long_columns
    columns = np.repeat(np.arange(size), counts)
    shuffled = rng.permutation(matrix.nnz)
    built = ones_at(matrix.indices[shuffled], columns[shuffled], (size, size))
    indptr, indices, values = (np.array(part).ravel() for part in built.CCS)
    np.testing.assert_array_equal(indptr, matrix.indptr)
    np.testing.assert_array_equal(indices, matrix.indices)
    np.testing.assert_array_equal(values, 1.0)


def test_superlu_keeps_the_fill_of_its_first_minimum_degree_ordering():
    """The SuperLU backend orders the columns once (minimum degree, at its first factorisation)
    and then factorises the matrix permuted by that ordering: its factor holds no more entries
    than SuperLU's own minimum-degree factorisation of the same matrix. Permuted by the inverse
    ordering instead, a 10 × 20 sphere's factor held 4.1× as many, and intel's 25×."""
    graph = sphere(10, 20, seed=3)[0]
    system = NormalEquations(graph, graph.gauge_nodes(), "scipy")
    lin = linearize_between(graph.values, graph.edges)
    prior_lin = linearize_priors(graph.values, graph.priors)
    data = system.normal_matrix(lin, graph.edges.information, prior_lin, graph.priors.information)
    reference = scipy.sparse.linalg.splu(
        system.matrix(data),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    for _ in range(2):  # the first factorisation chooses the ordering, the second reuses it
        system.factorize(data)
        assert system.cholesky._lu.L.nnz <= reference.L.nnz


@pytest.mark.parametrize("backend", available_backends())
def test_a_node_that_every_pose_measures_solves_as_dense(backend):
    """A docking station that all 32 poses measure: one dense row and column of blocks, early
    in the order, whose lower-triangle columns CHOLMOD's pattern builds transposed."""
    graph = docked(*sphere(4, 8, seed=11), seed=12)[0]
    held = np.array([0])
    system = NormalEquations(graph, held, backend)
    columns = np.repeat(np.arange(system.size), np.diff(system.indptr))
    lower_counts = np.bincount(columns[system.indices >= columns], minlength=system.size)
    assert np.flatnonzero(builds_transposed(lower_counts)).tolist() == list(range(6))
    _assert_matches_dense(system, graph, held, 0.0)


def test_pattern_holds_one_block_per_node_and_edge_pair():
    graph = random_graph(POSE_GROUPS[1], 10, 0, seed=7)  # a chain: 9 edges
    system = NormalEquations(graph, np.array([0]))
    free, d = 9, 6
    chain_pairs = 8  # edges between two free nodes
    assert system.nnz == (free + 2 * chain_pairs) * d * d


PATTERN_ARRAYS = (
    "indptr",
    "indices",
    "diagonal_positions",
    "_block_positions",
    "_vector_positions",
    "_block_keys",
)
"""What a grown pattern must hold as one built afresh does: CSC arrays, and where each stacked
block and vector piece is summed."""


def _grown(graph, seed: int, old_to_old: bool):
    """``graph`` with 6 nodes appended, joined to each other and to old nodes, and a prior;
    with ``old_to_old`` also a new edge between two old nodes."""
    rng = np.random.default_rng(seed)
    grown = graph.copy()
    d, old = graph.group.dof, graph.node_ids
    new = np.arange(6) + old.max() + 1
    grown.add_nodes(new, graph.group.exp(0.3 * rng.normal(size=(6, d))))
    i = np.concatenate([new[:-1], new[[0, 3]], old[1:2] if old_to_old else []])
    j = np.concatenate([new[1:], old[[2, 7]], old[-1:] if old_to_old else []])
    measured = graph.group.exp(0.3 * rng.normal(size=(i.size, d)))
    grown.add_edges(i, j, measured, np.eye(d) * 3.0)
    grown.add_priors(new[:1], measured[:1], np.eye(d))
    return grown


@pytest.mark.parametrize("old_to_old", [False, True], ids=["appended", "with-old-loop"])
@pytest.mark.parametrize("backend", available_backends())
def test_a_grown_pattern_equals_one_built_afresh(backend, old_to_old):
    graph = random_graph(POSE_GROUPS[1], 12, 6, seed=8, priors=1)
    held = np.array([0, 4])
    previous = NormalEquations(graph, held, backend)
    grown = _grown(graph, 9, old_to_old)
    system = NormalEquations(grown, held, backend, previous=previous)
    fresh = NormalEquations(grown, held, backend)
    assert system.grown and not fresh.grown
    _assert_same_pattern(system, fresh)
    _assert_matches_dense(system, grown, held, 0.0)


def _assert_same_pattern(system, fresh):
    for name in PATTERN_ARRAYS:
        np.testing.assert_array_equal(getattr(system, name), getattr(fresh, name))
    if system.cholesky.name == "cholmod":
        np.testing.assert_array_equal(system.cholesky._lower, fresh.cholesky._lower)


@pytest.mark.parametrize("backend", available_backends())
def test_a_pattern_grown_pose_by_pose_equals_one_built_afresh(backend):
    """As a back end grows it: one pose per step, by odometry and a loop closure to an old
    pose, each pattern grown from the last; node 0 held, so blocks go to the trash slot."""
    group = POSE_GROUPS[0]
    graph = random_graph(group, 8, 3, seed=12)
    held = np.array([0])
    system = NormalEquations(graph, held, backend)
    rng = np.random.default_rng(13)
    for step in range(5):
        new = graph.node_ids.max() + 1
        graph.add_nodes([new], group.exp(0.3 * rng.normal(size=(1, group.dof))))
        measured = group.exp(0.3 * rng.normal(size=(2, group.dof)))
        old = graph.node_ids[2 * step % 5]
        graph.add_edges([new - 1, old], [new, new], measured, np.eye(group.dof) * 2.0)
        system = NormalEquations(graph, held, backend, previous=system)
        assert system.grown
        _assert_same_pattern(system, NormalEquations(graph, held, backend))
        _assert_matches_dense(system, graph, held, 0.0)


@pytest.mark.parametrize("held", [[0, 1, 2, 3], [0, 1]], ids=["every-node-held", "two-held"])
def test_a_pattern_grows_by_edges_and_priors_between_held_nodes(held):
    """Blocks of held nodes (index −1) are kept out of the merge, even when no node is free
    and the old and new block lists are empty."""
    graph = random_graph(POSE_GROUPS[0], 4, 0, seed=11)
    graph.add_prior(graph.node_ids[0], graph.values[0], np.eye(3))
    held = np.array(held)
    previous = NormalEquations(graph, held)
    grown = graph.copy()
    grown.add_edge(graph.node_ids[0], graph.node_ids[1], graph.values[1], np.eye(3))
    grown.add_prior(graph.node_ids[1], graph.values[1], np.eye(3))
    system = NormalEquations(grown, held, previous=previous)
    assert system.grown
    _assert_same_pattern(system, NormalEquations(grown, held))
    _assert_matches_dense(system, grown, held, 0.0)


def test_a_pattern_is_rebuilt_when_the_graph_did_not_only_grow():
    graph = random_graph(POSE_GROUPS[0], 12, 6, seed=10)
    held = np.array([0])
    previous = NormalEquations(graph, held)
    shrunk = graph.copy()
    shrunk.remove_edges([3])
    assert not NormalEquations(shrunk, held, previous=previous).grown
    assert not NormalEquations(graph, np.array([1]), previous=previous).grown  # other gauge
    assert NormalEquations(graph, held, previous=previous).grown  # nothing appended


@pytest.mark.parametrize("backend", [*available_backends(), "cg"])
def test_inverse_form_of_sparse_columns_equals_the_dense_product(backend):
    """Bᵀ H⁻¹ B for a sparse B given by its entries (one of them repeated, which adds up)
    equals the product of dense matrices, for every backend (CHOLMOD's by sparse solves)."""
    graph = random_graph(POSE_GROUPS[1], 30, 12, seed=7, priors=1)
    system = NormalEquations(graph, graph.gauge_nodes(), backend)
    lin = linearize_between(graph.values, graph.edges)
    prior_lin = linearize_priors(graph.values, graph.priors)
    data = system.normal_matrix(lin, graph.edges.information, prior_lin, graph.priors.information)
    system.factorize(data)
    rng = np.random.default_rng(3)
    count = 7
    rows = np.append(rng.integers(0, system.size, 40), 0)
    columns = np.append(rng.integers(0, count, 40), 0)
    values = np.append(rng.normal(size=40), 0.5)
    rows[0], columns[0] = 0, 0  # the entry (0, 0) twice
    dense_b = np.zeros((system.size, count))
    np.add.at(dense_b, (rows, columns), values)
    hessian = _dense_system(graph, graph.gauge_nodes())[0]
    expected = dense_b.T @ np.linalg.solve(hessian, dense_b)
    form = system.cholesky.inverse_form(rows, columns, values, count)
    np.testing.assert_allclose(form, expected, rtol=1e-8, atol=1e-10 * np.abs(expected).max())
