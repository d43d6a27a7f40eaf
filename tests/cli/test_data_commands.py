"""``generate``, ``datasets`` and ``bench`` after a plain install (gtsam hidden)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sys

import numpy as np
import pytest
from posegraph_cli.main import main
from posegraph_cli.schema import SCHEMAS
from posegraph_datasets import download

import posegraph
from posegraph.io import read_graph
from posegraph.io.trajectories import read_trajectory
from tests.cli.helpers import EXAMPLE, jsonschema


def _run(arguments: list[str]) -> tuple[int, str]:
    """Exit code and stdout of the command, in process; a JSON document is checked against its
    schema."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(arguments)
    if "--json" in arguments and code == 0:
        jsonschema.validate(json.loads(out.getvalue()), SCHEMAS[arguments[0]])
    return code, out.getvalue()


@pytest.fixture
def mirror(tmp_path, monkeypatch):
    """A local mirror holding one graph (the bundled example, under a name of the registry with
    its SHA-256), as ``datasets download`` reads it; downloads go to ``tmp_path/cache``."""
    folder = tmp_path / "mirror"
    folder.mkdir()
    contents = open(EXAMPLE, "rb").read()
    (folder / "tinyGrid3D.g2o").write_bytes(contents)
    graphs = {"tinyGrid3D.g2o": hashlib.sha256(contents).hexdigest()}
    monkeypatch.setattr(download, "GRAPHS", graphs)
    monkeypatch.setenv(download.URL_ENV, folder.as_uri())
    monkeypatch.setenv(download.DATASETS_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr("posegraph_datasets.paths.shared_datasets_dir", lambda: None)
    return folder


def test_datasets_download_checks_the_sha256_and_writes_nothing_on_a_mismatch(mirror, tmp_path):
    code, out = _run(["datasets", "download", "all", "--json"])
    document = json.loads(out)
    assert code == 0 and document["graphs"][0]["downloaded"]
    path = tmp_path / "cache" / "tinyGrid3D.g2o"
    assert path.read_bytes() == (mirror / "tinyGrid3D.g2o").read_bytes()
    assert not json.loads(_run(["datasets", "download", "tinygrid3d", "--json"])[1])["graphs"][0][
        "downloaded"
    ]  # already there, by any case of its name
    (mirror / "tinyGrid3D.g2o").write_text("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n")  # tampered
    with pytest.raises(download.DownloadError, match="SHA-256"):
        download.download("tinyGrid3D.g2o", tmp_path / "elsewhere")
    assert not (tmp_path / "elsewhere" / "tinyGrid3D.g2o").exists()
    assert main(["datasets", "download", "nosuchgraph"]) == 2
    (mirror / "tinyGrid3D.g2o").unlink()  # the mirror lost it: one line naming the address
    with pytest.raises(download.DownloadError, match="tinyGrid3D.g2o: cannot fetch"):
        download.download("tinyGrid3D.g2o", tmp_path / "elsewhere")
    listed = json.loads(_run(["datasets", "list", "--json"])[1])["graphs"]
    assert listed == [{"name": "tinyGrid3D.g2o", "path": str(path)}]


def test_bench_runs_without_gtsam_on_a_downloaded_graph(mirror, monkeypatch, capsys):
    """A plain install has no gtsam: bench gives posegraph's columns, gtsam's empty, and says how
    to add them."""
    assert main(["datasets", "download", "tinyGrid3D", "--quiet"]) == 0
    monkeypatch.setitem(sys.modules, "gtsam", None)  # import gtsam raises ImportError
    assert main(["bench", "--graphs", "tinyGrid3D", "--repeats", "1"]) == 0
    captured = capsys.readouterr()
    assert "pip install 'posegraph[bench]'" in captured.err
    row = next(line for line in captured.out.splitlines() if line.startswith("| tinyGrid3D"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[2] == "–" and float(cells[7]) > 0  # gtsam's time; posegraph's error
    document = json.loads(_run(["bench", "--graphs", "tinyGrid3D", "--repeats", "1", "--json"])[1])
    assert document["gtsam"] is False


@pytest.mark.parametrize("kind", ["sphere", "grid", "manhattan", "monocular"])
def test_generate_writes_a_graph_and_its_ground_truth(kind, tmp_path):
    graph_path, truth_path = tmp_path / f"{kind}.g2o", tmp_path / "truth.tum"
    code, out = _run(["generate", kind, str(graph_path), "--truth", str(truth_path), "--json"])
    document = json.loads(out)
    graph = read_graph(str(graph_path)).graph
    truth = read_trajectory(str(truth_path), "tum")
    assert code == 0 and document["nodes"] == graph.num_nodes == len(truth.keys)
    np.testing.assert_array_equal(truth.keys, graph.node_ids)
    dims = 2 if graph.group is posegraph.SE2 else 3
    extent = np.ptp(truth.positions, axis=0).max()
    start = np.linalg.norm(graph.positions(graph.node_ids) - truth.positions[:, :dims], axis=1)
    assert start[0] < 1e-12 and start.max() > 1e-3 * extent  # dead reckoning from the truth
    if kind != "monocular":  # its odometry drifts in scale: scale-drift's job
        posegraph.optimize(graph)
        solved = graph.positions(graph.node_ids) - truth.positions[:, :dims]
        assert np.linalg.norm(solved, axis=1).max() < 0.1 * extent


def test_generate_false_loops_appends_them_last(tmp_path):
    source, corrupted = tmp_path / "m.g2o", tmp_path / "loops.g2o"
    assert main(["generate", "manhattan", str(source), "--quiet"]) == 0
    code, out = _run(["generate", "false-loops", str(corrupted), "--from", str(source), "--json"])
    original, loops = read_graph(str(source)).graph, read_graph(str(corrupted)).graph
    false = json.loads(out)["false_edges"]
    assert false > 0 and loops.num_edges == original.num_edges + false
    np.testing.assert_array_equal(loops.edges.i[: original.num_edges], original.edges.i)
    assert main(["generate", "false-loops", str(tmp_path / "other.g2o")]) == 2  # no --from


def test_trajectories_are_first_class(tmp_path):
    """plot draws TUM, KITTI and EuRoC files; convert makes an odometry graph of a trajectory;
    optimize writes KITTI with --to; eval reads EuRoC's CSV (time stamps in ns, quaternion
    w first); KITTI files of different lengths are refused unless --match-by-index."""
    from tests.cli.helpers import assert_not_blank

    graph, truth = tmp_path / "s.g2o", tmp_path / "truth.tum"
    assert main(["generate", "sphere", str(graph), "--truth", str(truth), "--quiet"]) == 0
    rows = np.loadtxt(truth)
    euroc = tmp_path / "data.csv"
    lines = [
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],v_x"
    ]
    lines += [f"{int(r[0] * 1e9)},{r[1]},{r[2]},{r[3]},{r[7]},{r[4]},{r[5]},{r[6]},0" for r in rows]
    euroc.write_text("\n".join(lines) + "\n")
    figure = tmp_path / "trajectories.png"
    assert main(["plot", str(truth), str(euroc), str(graph), "-o", str(figure), "--quiet"]) == 0
    assert_not_blank(figure)

    odometry = tmp_path / "odometry.g2o"
    assert main(["convert", str(truth), str(odometry), "--sigmas", "0.2", "0.02", "--quiet"]) == 0
    converted = read_graph(str(odometry)).graph
    assert converted.num_edges == len(rows) - 1
    np.testing.assert_allclose(converted.edges.information[0], np.diag([25.0] * 3 + [2500.0] * 3))
    np.testing.assert_allclose(converted.positions(converted.node_ids), rows[:, 1:4], atol=1e-9)

    kitti = tmp_path / "estimate.txt"
    assert main(["optimize", str(graph), "-o", str(kitti), "--to", "kitti", "--quiet"]) == 0
    assert np.loadtxt(kitti).shape == (len(rows), 12)

    code, out = _run(["eval", str(truth), str(euroc), "--json"])
    document = json.loads(out)
    assert code == 0 and document["matched_poses"] == len(rows)
    assert document["ate"]["rmse"] < 1e-6  # the same poses

    truth_kitti, short = tmp_path / "truth.kitti", tmp_path / "short.kitti"
    assert main(["convert", str(truth), str(truth_kitti), "--quiet"]) == 0
    short.write_text("".join(open(kitti).readlines()[:150]))
    assert main(["eval", str(short), str(truth_kitti)]) == 2
    code, out = _run(["eval", str(short), str(truth_kitti), "--match-by-index", "--json"])
    assert code == 0 and json.loads(out)["matched_poses"] == 150
