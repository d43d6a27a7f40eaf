"""Reading g2o and TORO: every tag, FIX, the reading options, nodes without vertex lines, lenient
and strict reading."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from posegraph_datasets import example

import posegraph
from posegraph.analysis.doctor import diagnose
from posegraph.graph import PoseGraph
from posegraph.io import GraphFileError, ReadOptions, load_graph, read_graph, write_graph
from posegraph.io.records import REPAIR_ADVICE
from posegraph.lie import SE2, SE3, Sim3
from posegraph.problem.factors import chi2
from posegraph.solvers import solve
from tests.io.helpers import assert_same_graph

from ..conftest import random_graph

EDGE2_INFORMATION = np.array([[4.0, 1.0, 0.5], [1.0, 9.0, 2.0], [0.5, 2.0, 16.0]])

EDGE2_VALUES = {"toro": "4 1 9 16 0.5 2", "g2o": "4 1 0.5 9 2 16"}

INFORMATION_VALUES = {"EDGE_SE2": 6, "EDGE2": 6, "EDGE_SE3:QUAT": 21, "EDGE3": 21}

INFORMATION_VALUES["EDGE_SIM3:EXPMAP"] = 28


def _edge_lines(graph):
    from posegraph.io.writer import format_g2o

    return [line for line in format_g2o(graph).splitlines() if line.startswith("EDGE")]


def _refused_leniently(path, text: str) -> str:
    """The error of reading ``text``, written to ``path``, leniently."""
    path.write_text(text)
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path), ReadOptions(lenient=True))
    return str(raised.value)


INFORMATION_SE2 = "1 0 0 1 0 1"


def test_se3_prior_is_on_the_pose_times_its_offset(tmp_path):
    """g2o's EDGE_SE3_PRIOR weighs r = Log(Z⁻¹ X O), O its PARAMS_SE3OFFSET."""
    rng = np.random.default_rng(7)
    offset, measurement = SE3.sample(rng), SE3.sample(rng)
    information = rng.normal(size=(6, 6))
    information = information @ information.T + np.eye(6)
    upper = information[np.triu_indices(6)]

    def pose_text(pose):
        q, t = pose.as_quaternion_translation()
        return " ".join(repr(x) for x in np.concatenate([t, q]).tolist())

    path = tmp_path / "prior.g2o"
    path.write_text(
        f"PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1\nPARAMS_SE3OFFSET 4 {pose_text(offset)}\n"
        f"VERTEX_SE3:QUAT 7 0 0 0 0 0 0 1\n"
        f"EDGE_SE3_PRIOR 7 4 {pose_text(measurement)} {' '.join(map(repr, upper.tolist()))}\n"
    )
    graph = read_graph(str(path)).graph
    for _ in range(3):
        pose = SE3.sample(rng)
        graph.set_values(SE3(pose.rotation[None], pose.translation[None]))
        r = measurement.inverse().compose(pose).compose(offset).log()
        assert chi2(graph.values, graph.edges, graph.priors) == pytest.approx(
            r @ information @ r, rel=1e-9
        )
    written = tmp_path / "written.g2o"
    write_graph(graph, str(written))
    assert written.read_text().startswith("PARAMS_SE3OFFSET 0 0.0 0.0 0.0 0.0 0.0 0.0 1.0\n")
    again = read_graph(str(written)).graph
    np.testing.assert_allclose(again.priors.information, graph.priors.information, rtol=1e-12)


def test_sim3_dialects_describe_the_same_graph(tmp_path):
    graph = random_graph(Sim3, 6, 3, seed=33)
    write_graph(graph, str(tmp_path / "a.g2o"), sim3_dialect="a")
    write_graph(graph, str(tmp_path / "b.g2o"), sim3_dialect="b")
    assert_same_graph(
        read_graph(str(tmp_path / "a.g2o")).graph, read_graph(str(tmp_path / "b.g2o")).graph, 1e-10
    )


def test_sim3_vertex_is_the_inverse_of_gs_world_to_camera_element(tmp_path):
    """Dialect (a) stores Sᵢ (world → camera); our node is Xᵢ = Sᵢ⁻¹ (CONVENTIONS.md)."""
    path = tmp_path / "v.g2o"
    path.write_text(
        "VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1\n"
        "VERTEX_SIM3:EXPMAP 1 0 0 0.7071067811865476 0.7071067811865476 1 2 3 2\n"
        + "EDGE_SIM3:EXPMAP 0 1 0 0 0 1 1 0 0 0.5 "
        + " ".join(
            ["1"]
            + ["0"] * 6
            + ["1"]
            + ["0"] * 5
            + ["1"]
            + ["0"] * 4
            + ["1", "0", "0", "0", "1", "0", "0", "1", "0", "1"]
        )
        + "\n"
    )
    graph = read_graph(str(path)).graph
    s = Sim3.from_quaternion_translation_scale(
        np.array([0, 0, 0.7071067811865476, 0.7071067811865476]), np.array([1.0, 2, 3]), 2.0
    )
    np.testing.assert_allclose(graph.values[1].as_matrix(), s.inverse().as_matrix(), atol=1e-12)
    z = Sim3(np.eye(3), np.array([1.0, 0, 0]), 0.5)
    np.testing.assert_allclose(
        graph.edges.measurements[0].as_matrix(), z.inverse().as_matrix(), atol=1e-12
    )


def test_fix_lines_are_honoured(tmp_path):
    graph = random_graph(SE2, 10, 6, seed=35, noise=0.2)
    path = tmp_path / "fix.g2o"
    write_graph(graph, str(path))
    path.write_text(path.read_text() + f"FIX {graph.node_ids[2]} {graph.node_ids[7]}\n")
    read = read_graph(str(path)).graph
    assert set(read.node_ids[read.fixed]) == {graph.node_ids[2], graph.node_ids[7]}
    result = solve(read)
    np.testing.assert_array_equal(
        result.values[read.fixed].as_matrix(), read.values[read.fixed].as_matrix()
    )
    assert result.summary.final_error < result.summary.initial_error
    # The fixed nodes are the gauge: the lowest id is free.
    assert not np.array_equal(result.values[0].as_matrix(), read.values[0].as_matrix())


def test_g2o_rotation_information_option(tmp_path):
    """g2o weighs the quaternion vector part (≈ φ/2): Λ_φφ = Λ_qq/4, Λ_ρφ = Λ_ρq/2."""
    graph = random_graph(SE3, 4, 1, seed=36)
    path = tmp_path / "g.g2o"
    write_graph(graph, str(path))
    as_is = read_graph(str(path)).graph.edges.information
    faithful = read_graph(
        str(path), ReadOptions(g2o_rotation_information=True)
    ).graph.edges.information
    np.testing.assert_allclose(faithful[:, :3, :3], as_is[:, :3, :3])
    np.testing.assert_allclose(faithful[:, 3:, 3:], as_is[:, 3:, 3:] / 4)
    np.testing.assert_allclose(faithful[:, :3, 3:], as_is[:, :3, 3:] / 2)
    # Writing with the same option restores the file's numbers.
    write_graph(
        read_graph(str(path), ReadOptions(g2o_rotation_information=True)).graph,
        str(tmp_path / "h.g2o"),
        g2o_rotation_information=True,
    )
    np.testing.assert_allclose(
        read_graph(str(tmp_path / "h.g2o")).graph.edges.information, as_is, rtol=1e-14
    )


@pytest.mark.parametrize("order", ["toro", "g2o"])
def test_edge2_information_in_either_order(order, tmp_path):
    path = tmp_path / "e.graph"
    path.write_text(f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 {EDGE2_VALUES[order]}\n")
    graph = read_graph(str(path), ReadOptions(edge2_order=order)).graph
    np.testing.assert_array_equal(graph.edges.information[0], EDGE2_INFORMATION)
    other = "g2o" if order == "toro" else "toro"
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path), ReadOptions(edge2_order=other))
    message = str(raised.value)
    assert message.startswith(f"{path}:3: EDGE2: information matrix is not positive semi-definite")
    assert f"read it with --edge2-order {order} (ReadOptions(edge2_order='{order}'))" in message


def test_edge2_order_gives_no_advice_when_neither_order_is_positive_semi_definite(tmp_path):
    path = tmp_path / "e.graph"
    path.write_text("VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 -1 0 0\n")
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    assert "--edge2-order" not in str(raised.value)


def test_unknown_edge2_order_is_refused():
    with pytest.raises(ValueError, match="edge2_order must be one of toro, g2o, not 'upper'"):
        ReadOptions(edge2_order="upper")


@pytest.mark.parametrize(
    "group, suffix",
    [(SE2, "g2o"), (SE3, "g2o"), (Sim3, "g2o"), (SE2, "graph"), (SE3, "graph")],
    ids=lambda v: getattr(v, "__name__", v),
)
def test_identity_information_ignores_or_replaces_the_files(group, suffix, tmp_path):
    """TORO's -ic: every edge weighs as the identity, and lines may omit their information."""
    graph = random_graph(group, 8, 4, seed=38)
    full = tmp_path / f"full.{suffix}"
    write_graph(graph, str(full))
    as_written = read_graph(str(full)).graph
    identity = read_graph(str(full), ReadOptions(identity_information=True)).graph
    eye = np.broadcast_to(np.eye(group.dof), graph.edges.information.shape)
    np.testing.assert_array_equal(identity.edges.information, eye)
    as_written.edges = dataclasses.replace(as_written.edges, information=eye.copy())
    assert_same_graph(identity, as_written)

    lines = full.read_text().splitlines()
    stripped_lines = [
        " ".join(line.split()[: -INFORMATION_VALUES[line.split()[0]]])
        if line.split()[0] in INFORMATION_VALUES
        else line
        for line in lines
    ]
    stripped = tmp_path / f"stripped.{suffix}"
    stripped.write_text("\n".join(stripped_lines) + "\n")
    assert_same_graph(
        read_graph(str(stripped), ReadOptions(identity_information=True)).graph, identity
    )
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(stripped))
    first_edge = next(k for k, line in enumerate(lines, 1) if line.startswith("EDGE"))
    without_information = sum(line.split()[0] in INFORMATION_VALUES for line in lines)
    assert str(raised.value).startswith(f"{stripped}:{first_edge}: ")
    assert str(raised.value).endswith(
        "the line has no information matrix (--identity-information weighs every edge by the"
        f" identity, as TORO's -ic does) (the first of {without_information} bad lines found)"
    )


def test_nodes_without_vertices_follow_the_odometry_chain(tmp_path):
    """With no VERTEX lines, node k+1 = node k · Z(k → k+1), from the identity at the lowest id."""
    graph = random_graph(SE2, 12, 6, seed=37)
    text = "".join(line + "\n" for line in _edge_lines(graph))
    path = tmp_path / "edges.g2o"
    path.write_text(text)
    assert not read_graph(str(path)).graph.initialized.any()  # the file gives no value
    result = load_graph(str(path))
    np.testing.assert_array_equal(result.nodes_without_vertex, graph.node_ids)
    expected = SE2.identity()
    values = result.graph.values
    np.testing.assert_allclose(values[0].as_matrix(), expected.as_matrix(), atol=1e-15)
    chain = result.graph.edges
    for k in range(graph.num_nodes - 1):
        edge = np.flatnonzero((chain.i == k) & (chain.j == k + 1))[0]
        expected = expected @ chain.measurements[edge]
        np.testing.assert_allclose(values[k + 1].as_matrix(), expected.as_matrix(), atol=1e-12)


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_position_only_priors_are_read_back(group, tmp_path):
    """A prior whose information is singular (a GNSS fix: no rotation information) is what the
    library accepts; the reader refused it ("not positive definite, λ_min = 0"), so such a graph
    could be written but not read back. A zero matrix, or a negative eigenvalue, is refused."""
    graph = random_graph(group, 6, 0, seed=57, priors=0)
    d = group.point_dim
    information = np.zeros((group.dof, group.dof))
    information[:d, :d] = np.diag(np.arange(1.0, d + 1))
    graph.add_priors(graph.node_ids[[0, 3]], graph.values[[0, 3]], information)
    path = tmp_path / "gnss.g2o"
    write_graph(graph, str(path))
    back = read_graph(str(path)).graph
    np.testing.assert_allclose(back.priors.information, graph.priors.information, atol=1e-12)
    tag = "EDGE_PRIOR_SE2" if group is SE2 else "EDGE_SE3_PRIOR"
    text = path.read_text()
    prior_line = next(line for line in text.splitlines() if line.startswith(tag))
    count = {SE2: 6, SE3: 21}[group]  # information values at the end of the line
    kept = prior_line.split()[:-count]
    zero, negative = [0.0] * count, [-1.0] + [0.0] * (count - 1)
    for values, message in [
        (zero, r"information matrix is zero \(it would weigh nothing\)"),
        (negative, r"information matrix is not positive semi-definite \(λ_min = -1\)"),
    ]:
        path.write_text(text.replace(prior_line, " ".join(kept + [str(v) for v in values])))
        with pytest.raises(GraphFileError, match=message):
            read_graph(str(path))


def test_a_file_without_vertices_is_composed_onto_its_fixes(tmp_path):
    """Odometry and GNSS fixes far from the origin, with no vertex lines: the composed values
    (what ``info`` measures the initial error at) are placed on the fixes."""
    path = tmp_path / "gnss.g2o"
    odometry = "".join(f"EDGE_SE2 {k} {k + 1} 1 0 0.05 100 0 0 100 0 1000\n" for k in range(30))
    path.write_text(
        odometry
        + "EDGE_PRIOR_SE2 0 500000 4000000 0 1 0 0 1 0 0\n"
        + "EDGE_PRIOR_SE2 30 499990 4000020 0 1 0 0 1 0 0\n"
    )
    graph = load_graph(str(path)).graph
    spread = np.linalg.norm(
        graph.positions([0, 30]) - [[500000, 4000000], [499990, 4000020]], axis=1
    )
    assert spread.max() < 5.0  # the chain is curved, the fixes are not its ends exactly
    assert chi2(graph.values, graph.edges, graph.priors) < 100.0


def test_broken_chain_is_bridged_by_other_edges(tmp_path):
    """Without the edge 3 → 4, node 4 is reached through a loop edge (or its inverse)."""
    graph = PoseGraph(SE2)
    truth = SE2.exp(np.random.default_rng(38).normal(size=(6, 3)))
    graph.add_nodes(np.arange(6), truth)
    i, j = np.array([0, 1, 2, 4, 5]), np.array([1, 2, 3, 5, 2])  # edge 5 → 2 bridges the gap
    graph.add_edges(i, j, truth[i].between(truth[j]), np.eye(3))
    path = tmp_path / "bridge.g2o"
    path.write_text("".join(line + "\n" for line in _edge_lines(graph)))
    values = load_graph(str(path)).graph.values
    aligned = truth[0].inverse() @ truth  # the reader starts node 0 at the identity
    np.testing.assert_allclose(values.as_matrix(), aligned.as_matrix(), atol=1e-12)


def test_lenient_mode_skips_and_reports(tmp_path):
    path = tmp_path / "mixed.g2o"
    path.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
        "ROBOTLASER1 whatever 1 2 3\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
        "EDGE_SE2 1 2 1 0 nan 1 0 0 1 0 1\n"
        "EDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\n"
    )
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    assert str(raised.value) == (
        f"{path}:4: unknown tag 'ROBOTLASER1' (--lenient skips lines it cannot read)"
    )
    result = read_graph(str(path), ReadOptions(lenient=True))
    assert result.skipped == [
        (4, "unknown tag 'ROBOTLASER1'"),
        (6, "EDGE_SE2: NaN or infinite value"),
    ]
    assert result.graph.num_edges == 2
    assert result.tag_counts == {"VERTEX_SE2": 3, "EDGE_SE2": 2}
    # A file of which nothing could be read is an error, not an empty graph.
    nothing = tmp_path / "nothing.g2o"
    assert _refused_leniently(nothing, "VERTEX_SE2 0 0 0\nROBOTLASER1 whatever\n") == (
        f"{nothing}: holds no vertex or edge that could be read (2 line(s) skipped: 1 × VERTEX_SE2:"
        " expected 4 numbers after the tag, found 3 (first at line 1); 1 × unknown tag"
        " 'ROBOTLASER1' (first at line 2))"
    )
    # Nor is a file of which every line has an unknown tag: it says so, not "is it empty?".
    unknown = tmp_path / "unknown.g2o"
    lines = "# a comment\nROBOTLASER1 whatever\nROBOTLASER1 1 2\n"
    assert _refused_leniently(unknown, lines) == (
        f"{unknown}: holds no vertices or edges (2 line(s) skipped: 2 × unknown tag"
        " 'ROBOTLASER1' (first at line 2))"
    )


def test_landmark_lines_are_named_and_lenient_reading_leaves_them_out(tmp_path):
    path = tmp_path / "landmarks.g2o"
    path.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 2 1 1\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2_XY 0 2 1 1 1 0 1\n"
    )
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    assert str(raised.value) == (
        f"{path}:3: landmark tag 'VERTEX_XY': posegraph optimises poses only (--lenient"
        " leaves the landmarks out) (the first of 2 bad lines found)"
    )
    result = read_graph(str(path), ReadOptions(lenient=True))
    assert result.skipped == [
        (3, "landmark tag 'VERTEX_XY': posegraph optimises poses only"),
        (5, "landmark tag 'EDGE_SE2_XY': posegraph optimises poses only"),
    ]
    assert (result.graph.num_nodes, result.graph.num_edges) == (2, 1)


def test_lenient_mode_skips_sim3_lines_the_graph_would_refuse(tmp_path):
    """A Sim3 pose of negative scale, or of a scale whose inverse's determinant underflows to 0,
    is refused on its line (strict) or skipped (lenient), as the graph would refuse it. Strict
    reading names the earliest (an edge, though vertices are checked first); the skipped lines
    are listed in line order."""
    path = tmp_path / "scales.g2o"
    information = " ".join(["0"] * 28)
    identity = "0 0 0 1 0 0 0"
    path.write_text(
        f"VERTEX_SIM3:EXPMAP 0 {identity} 1\n"
        f"EDGE_SIM3:EXPMAP 0 1 {identity} -1 {information}\n"
        f"VERTEX_SIM3:EXPMAP 1 {identity} 2\n"
        f"VERTEX_SIM3:EXPMAP 2 {identity} 1e120\n"
    )
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    assert raised.value.line == 2 and "determinant -1" in raised.value.message
    assert raised.value.message.endswith("(the first of 2 bad lines found)")
    result = read_graph(str(path), ReadOptions(lenient=True))
    assert [(line, "determinant" in why) for line, why in result.skipped] == [(2, True), (4, True)]
    assert result.graph.node_ids.tolist() == [0, 1] and result.graph.num_edges == 0


@pytest.mark.parametrize(
    "lines, line, message, count, skipped",
    [
        (  # each line's numbers: an edge before a vertex, though vertices are checked first
            [
                "VERTEX_SE2 0 0 0 0",
                f"EDGE_SE2 0 7 1 0 0 {INFORMATION_SE2}",  # what lines refer to: a later stage
                "VERTEX_SE2 1 1 0 0",
                "EDGE_SE2 0 2 1 0 0 1 0 0 1 0 -1",
                "VERTEX_SE2 2 1 0 nan",
                f"EDGE_SE2 1 2 1 0 0 {INFORMATION_SE2}",  # keeps node 2: its vertex was skipped
            ],
            4,
            "EDGE_SE2: information matrix is not positive semi-definite (λ_min = -1)"
            + REPAIR_ADVICE,
            2,
            [2, 4, 5],
        ),
        (  # what lines refer to: an edge to a missing node before a vertex defined again
            [
                "VERTEX_SE2 0 0 0 0",
                f"EDGE_SE2 0 5 1 0 0 {INFORMATION_SE2}",
                "VERTEX_SE2 1 1 0 0",
                "VERTEX_SE2 1 1 0 0",
                f"EDGE_SE2 0 1 1 0 0 {INFORMATION_SE2}",
            ],
            2,
            "EDGE_SE2: refers to node 5, which has no vertex line",
            2,
            [2, 4],
        ),
        (  # the tags come first: an unknown tag after a bad number
            ["VERTEX_SE2 0 0 0 0", "VERTEX_SE2 1 1 0 inf", "ROBOTLASER1 1 2 3"],
            3,
            "unknown tag 'ROBOTLASER1' (--lenient skips lines it cannot read)",
            1,
            [2, 3],
        ),
    ],
    ids=["numbers", "references", "tags"],
)
def test_strict_reading_names_the_earliest_bad_line_of_the_first_failing_stage(
    tmp_path, lines, line, message, count, skipped
):
    """Strict reading runs a stage's checks to the end, then names its earliest bad line and
    how many it found; lenient reading skips every bad line of every stage."""
    path = tmp_path / "several.g2o"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(GraphFileError) as raised:
        read_graph(str(path))
    more = f" (the first of {count} bad lines found)" if count > 1 else ""
    assert (raised.value.line, raised.value.message) == (line, message + more)
    assert [number for number, _ in read_graph(str(path), ReadOptions(lenient=True)).skipped] == (
        skipped
    )


def test_lenient_reading_keeps_the_edges_of_a_node_whose_vertex_line_it_skipped(tmp_path):
    """A bad vertex line costs its value, not its edges: the node stays in its vertex line's
    place, its value composed from its neighbours. A line that names only that node is
    skipped, saying why."""
    path = tmp_path / "bad_vertex.g2o"
    lines = [
        "VERTEX_SE2 0 0 0 0",
        "VERTEX_SE2 1 1 0 nan",
        "VERTEX_SE2 2 2 0 0",
        "VERTEX_SE2 3 3 0 0 0",
        f"EDGE_SE2 0 1 1 0 0 {INFORMATION_SE2}",
        f"EDGE_SE2 1 2 1 0 0 {INFORMATION_SE2}",
        f"EDGE_SE2 0 2 2 0 0 {INFORMATION_SE2}",
        "FIX 3",
    ]
    path.write_text("\n".join(lines) + "\n")
    assert not read_graph(str(path), ReadOptions(lenient=True)).graph.initialized[1]
    result = load_graph(str(path), ReadOptions(lenient=True))
    graph = result.graph
    assert result.skipped == [
        (2, "VERTEX_SE2: NaN or infinite value"),
        (4, "VERTEX_SE2: expected 4 numbers after the tag, found 5"),
        (8, "FIX: refers to node 3, whose vertex line (line 4) was skipped"),
    ]
    assert graph.node_ids.tolist() == [0, 1, 2] and graph.num_edges == 3
    assert result.nodes_without_vertex.tolist() == [1]
    np.testing.assert_allclose(graph.values.translation, [[0, 0], [1, 0], [2, 0]], atol=1e-12)
    np.testing.assert_allclose(graph.values.log()[:, 2], 0, atol=1e-12)
    problems = [p.what for p in diagnose(result).problems]
    assert "1 node(s) have no vertex line that was read" in problems

    # With every vertex line skipped, the file reads as one without them: nodes by id.
    lines = [
        "VERTEX_SE2 1 0 0 nan",
        "VERTEX_SE2 0 1 0 0 0",
        f"EDGE_SE2 0 1 1 0 0 {INFORMATION_SE2}",
        f"EDGE_SE2 1 2 1 0 0 {INFORMATION_SE2}",
    ]
    path.write_text("\n".join(lines) + "\n")
    result = load_graph(str(path), ReadOptions(lenient=True))
    assert result.graph.node_ids.tolist() == result.nodes_without_vertex.tolist() == [0, 1, 2]
    np.testing.assert_allclose(result.graph.values.translation, [[0, 0], [1, 0], [2, 0]])


def test_a_skipped_vertex_line_leaves_the_optimum_unchanged(tmp_path):
    """A vertex line holds only a starting value: with one spoilt, lenient reading keeps every
    measurement, so the bundled example optimises to the same error (chordal start) as when
    clean."""
    lines = example("manhattan_small.g2o").read_text().splitlines()
    spoilt = next(k for k, line in enumerate(lines) if line.startswith("VERTEX_SE2 200 "))
    lines[spoilt] += " 0"
    path = tmp_path / "spoilt.g2o"
    path.write_text("\n".join(lines) + "\n")
    clean = read_graph(str(example("manhattan_small.g2o"))).graph
    read = read_graph(str(path), ReadOptions(lenient=True))
    assert [line for line, _ in read.skipped] == [spoilt + 1]
    assert read.graph.node_ids.tolist() == clean.node_ids.tolist()
    assert read.graph.num_edges == clean.num_edges
    final = posegraph.optimize(read.graph).summary.final_error
    assert final == pytest.approx(posegraph.optimize(clean).summary.final_error, rel=1e-9)
