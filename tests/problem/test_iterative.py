"""Conjugate gradients in place of a filling factorisation, and the factor size that CHOLMOD's
symbolic analysis predicts, which chooses between them."""

from __future__ import annotations

import numpy as np
import pytest

from posegraph.api import optimize
from posegraph.lie import SE2, SE3
from posegraph.problem import backends
from posegraph.problem.backends import available_backends, make_cholesky
from posegraph.problem.cholesky import NotPositiveDefinite
from posegraph.problem.factor_size import predicted_column_counts, predicted_flops
from posegraph.problem.factors import linearize_between, linearize_priors
from posegraph.problem.iterative import FEW_COLUMNS, ConjugateGradients
from posegraph.problem.linear import NormalEquations
from posegraph.solvers import SolverOptions

from ..conftest import random_graph

needs_cholmod = pytest.mark.skipif("cholmod" not in available_backends(), reason="no cvxopt")


def _normal_matrix(graph):
    """The normal equations of ``graph`` (scipy's backend) and H's CSC data and g there."""
    system = NormalEquations(graph, graph.gauge_nodes(), "scipy")
    terms = (
        linearize_between(graph.values, graph.edges),
        graph.edges.information,
        linearize_priors(graph.values, graph.priors),
        graph.priors.information,
    )
    return system, system.normal_matrix(*terms), system.gradient(*terms)


def _with_recorded_fallback(system):
    """Conjugate gradients over ``system``'s pattern, and the list of the SuperLU factorisers
    they fall back to (made on first need)."""
    made = []

    def fallback():
        made.append(make_cholesky(system.indices, system.indptr, system.size, "scipy"))
        return made[-1]

    return ConjugateGradients(system.indices, system.indptr, system.size, fallback), made


@needs_cholmod
@pytest.mark.parametrize(("group", "nodes", "loops"), [(SE2, 60, 20), (SE3, 200, 300)])
def test_predicted_column_counts_are_those_of_the_computed_factor(group, nodes, loops):
    from cvxopt import spmatrix

    from posegraph.problem.cvxopt_import import import_cholmod

    cholmod = import_cholmod()
    system, data, _ = _normal_matrix(random_graph(group, nodes, loops, seed=3))
    n = system.size
    columns = np.repeat(np.arange(n), np.diff(system.indptr))
    lower = system.indices >= columns
    rows = system.indices[lower].tolist()
    matrix = spmatrix(data[lower].tolist(), rows, columns[lower].tolist(), (n, n))
    saved = dict(cholmod.options)
    cholmod.options["supernodal"] = 0  # a simplicial factor holds exactly the counted entries
    try:
        factor = cholmod.symbolic(matrix)
    finally:
        cholmod.options.clear()
        cholmod.options.update(saved)
    predicted = predicted_column_counts(factor, n)
    cholmod.numeric(matrix, factor)
    computed = np.diff(np.array(cholmod.getfactor(factor).CCS[0]).ravel())
    np.testing.assert_array_equal(predicted, computed)
    assert predicted_flops(factor, n) == pytest.approx(float(np.sum(computed.astype(float) ** 2)))


@needs_cholmod
def test_nothing_is_predicted_from_what_is_not_a_factor_of_that_size():
    from cvxopt import spmatrix

    from posegraph.problem.cvxopt_import import import_cholmod

    factor = import_cholmod().symbolic(spmatrix([2.0, 2.0], [0, 1], [0, 1]))
    assert predicted_column_counts(factor, 2) is not None
    assert predicted_column_counts(factor, 3) is None  # not the size the capsule holds
    assert predicted_column_counts(object(), 2) is None


@pytest.mark.parametrize("group", [SE2, SE3])
def test_conjugate_gradients_solve_as_the_direct_factorisation_does(group):
    system, data, gradient = _normal_matrix(random_graph(group, 80, 40, seed=5))
    direct = make_cholesky(system.indices, system.indptr, system.size, "scipy")
    direct.factorize(data)
    iterative_solver, made = _with_recorded_fallback(system)
    iterative_solver.factorize(data)
    expected = direct.solve(-gradient)
    np.testing.assert_allclose(iterative_solver.solve(-gradient), expected, rtol=1e-7, atol=1e-9)
    column = -gradient[:, None]
    np.testing.assert_allclose(
        iterative_solver.solve(column), direct.solve(column), rtol=1e-7, atol=1e-9
    )
    two = np.stack([-gradient, gradient + 1.0], axis=1)  # a few columns: one by one
    np.testing.assert_allclose(iterative_solver.solve(two), direct.solve(two), rtol=1e-7, atol=1e-9)
    assert not made  # conjugate gradients alone
    many = np.stack([gradient * k for k in range(1, FEW_COLUMNS + 2)], axis=1)
    np.testing.assert_allclose(iterative_solver.solve(many), direct.solve(many), rtol=1e-9)
    assert len(made) == 1  # more columns: the factor serves


@pytest.mark.parametrize("group", [SE2, SE3])
def test_the_preconditioner_takes_each_nodes_diagonal_block(group):
    """Block Jacobi: the normal equations' layout says where H's d × d diagonal blocks sit in
    the CSC data, node by node, and "cg" made for them solves as the direct factoriser does."""
    system, data, gradient = _normal_matrix(random_graph(group, 30, 10, seed=6))
    d, n = group.dof, system.size
    dense = np.zeros((n, n))
    dense[system.indices, np.repeat(np.arange(n), np.diff(system.indptr))] = data
    expected = [dense[k : k + d, k : k + d] for k in range(0, n, d)]
    np.testing.assert_array_equal(data[system.diagonal_blocks()], expected)
    solver = make_cholesky(
        system.indices, system.indptr, n, "cg", diagonal_blocks=system.diagonal_blocks()
    )
    solver.factorize(data)
    np.testing.assert_allclose(
        solver.solve(-gradient), np.linalg.solve(dense, -gradient), rtol=1e-7
    )
    assert solver.direct is None  # conjugate gradients alone


def test_a_matrix_that_is_not_positive_definite_falls_back_and_is_refused():
    system, data, gradient = _normal_matrix(random_graph(SE2, 30, 10, seed=1))
    indefinite = data.copy()
    diagonal = system.indices == np.repeat(np.arange(system.size), np.diff(system.indptr))
    indefinite[np.flatnonzero(diagonal)[4]] = -1.0
    solver, made = _with_recorded_fallback(system)
    solver.factorize(indefinite)
    with pytest.raises(NotPositiveDefinite):
        solver.solve(-gradient)
    assert len(made) == 1
    assert solver.pivots().shape == (system.size,)  # of the factorisation that failed


def test_covariances_and_pivots_come_from_the_direct_factoriser():
    system, data, _ = _normal_matrix(random_graph(SE3, 40, 10, seed=2))
    fastest = available_backends()[0]  # what "cg" falls back to
    direct = make_cholesky(system.indices, system.indptr, system.size, fastest)
    direct.factorize(data)
    solver = make_cholesky(system.indices, system.indptr, system.size, "cg")
    assert isinstance(solver, ConjugateGradients)
    solver.factorize(data)
    groups = np.arange(12).reshape(2, 6)
    np.testing.assert_allclose(
        solver.covariance_blocks(groups), direct.covariance_blocks(groups), rtol=1e-9
    )
    np.testing.assert_allclose(solver.pivots(), direct.pivots(), rtol=1e-9)


@needs_cholmod
def test_auto_takes_conjugate_gradients_only_where_the_factor_would_fill(monkeypatch):
    graph = random_graph(SE2, 300, 150, seed=4)
    system = NormalEquations(graph, graph.gauge_nodes(), "auto")
    assert system.cholesky.name == "cholmod"  # random loops over 300 poses fill little
    monkeypatch.setattr(backends, "FLOPS_PER_ENTRY", 0.0)
    assert NormalEquations(graph, graph.gauge_nodes(), "auto").cholesky.name == "cg"
    covariance = NormalEquations(graph, graph.gauge_nodes(), "auto", np.array([[0, 1]]))
    assert covariance.cholesky.name == "cholmod"  # covariances need the factor


@pytest.mark.parametrize("group", [SE2, SE3])
def test_levenberg_marquardt_with_conjugate_gradients_ends_where_it_does_with_a_factor(group):
    graph = random_graph(group, 120, 60, seed=7, noise=0.1)
    direct = optimize(graph.copy(), init="file", options=SolverOptions(linear_solver="scipy"))
    solved = optimize(graph.copy(), init="file", options=SolverOptions(linear_solver="cg"))
    assert solved.summary.linear_solver == "cg"
    assert solved.summary.converged
    assert solved.summary.final_error == pytest.approx(direct.summary.final_error, rel=1e-9)
    assert len(solved.summary.iterations) == len(direct.summary.iterations)
