"""``posegraph certify`` and ``optimize --certify``: the verdict, the JSON record (schema), and
a graph the check cannot take refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import grid

import posegraph
from posegraph.io import read_graph, write_graph
from tests.cli.helpers import run, run_json


@pytest.fixture
def grid_file(tmp_path) -> str:
    graph, _ = grid(size=3, seed=5)
    path = tmp_path / "grid.g2o"
    write_graph(graph, str(path))
    return str(path)


def test_certify_reports_the_verdict_and_posegraphs_own_optimum(grid_file):
    document = run_json("certify", grid_file)
    certificate = document["certificate"]
    assert certificate["verdict"] == "certified" and certificate["rank"] == 3
    assert certificate["smallest_eigenvalue"] >= -certificate["tolerance"]
    assert certificate["lower_bound"] <= certificate["objective"]
    # Levenberg-Marquardt from the certified estimate ends where posegraph's own run did.
    assert document["error_after_refining_certified"] == pytest.approx(
        document["posegraph_error"], rel=1e-8
    )
    text = run("certify", grid_file).stdout
    assert "certified globally optimal for SE-Sync's isotropic problem" in text


def test_optimize_certify_adds_the_certificate(grid_file, tmp_path):
    document = run_json("optimize", grid_file, "--certify")
    assert document["certificate"]["certified"]
    assert "certificate" not in run_json("optimize", grid_file)


def test_a_graph_with_priors_is_refused_in_one_line(tmp_path):
    graph, _ = grid(size=2, seed=6)
    graph.add_prior(0, graph.values[0], np.eye(6))
    path = tmp_path / "prior.g2o"
    write_graph(graph, str(path))
    completed = run("certify", path, check_exit=2)
    assert completed.stderr.strip().splitlines() == [
        "posegraph: error: SE-Sync's problem has no priors: certify a graph without them"
    ]


def test_info_certify_checks_what_it_can_and_says_why_not(grid_file, tmp_path):
    document = run_json("info", grid_file, "--certify")
    assert document["certificate"]["certified"]
    graph, _ = grid(size=2, seed=7)
    graph.add_prior(0, graph.values[0], np.eye(6))
    path = tmp_path / "prior.g2o"
    write_graph(graph, str(path))
    assert run_json("info", path, "--certify")["certificate"] is None
    assert (
        "certificate: not checked: SE-Sync's problem has no priors"
        in run("info", path, "--certify").stdout
    )


def test_certify_writes_the_certified_estimate_and_refuses_to_overwrite_its_input(
    grid_file, tmp_path
):
    output = tmp_path / "certified.g2o"
    document = run_json("certify", grid_file, "-o", output)
    assert document["output"] == str(output)
    written = read_graph(str(output)).graph
    optimised = read_graph(grid_file).graph
    posegraph.optimize(optimised)
    assert np.abs(written.values.as_matrix() - optimised.values.as_matrix()).max() < 1e-5
    refused = run("certify", grid_file, "-o", grid_file, check_exit=2)
    assert "refusing to overwrite an input file with -o" in refused.stderr


def test_a_robust_run_is_certified_on_the_measurements_it_kept(tmp_path):
    from posegraph_datasets.outliers import add_false_loops

    graph, _ = grid(size=3, seed=9)
    corrupted, false = add_false_loops(graph, 0.2, seed=9)
    path = tmp_path / "false_loops.g2o"
    write_graph(corrupted, str(path))
    document = run_json("certify", path, "--robust", "gnc")
    assert document["certificate"]["certified"]
    least_squares = run_json("certify", path)  # every loop, the false ones too
    assert least_squares["certificate"]["objective"] > 10 * document["certificate"]["objective"]
    assert run_json("optimize", path, "--robust", "gnc", "--certify")["certificate"][
        "objective"
    ] == (pytest.approx(document["certificate"]["objective"], rel=1e-6))
