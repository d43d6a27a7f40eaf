"""The shape of the code, as docs/architecture.md describes it: no import cycle (imports inside
functions and under TYPE_CHECKING count), small modules and functions, a data model that holds
data only, and an architecture page that names every module."""

from __future__ import annotations

import ast
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
from posegraph_datasets.outliers import add_false_loops

import posegraph
from posegraph import SE2

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "posegraph"
MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 60


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _imported(module: str, path: Path) -> set[str]:
    """The posegraph modules that ``module`` imports anywhere in its file (the most specific
    module each import names: ``from .graph import PoseGraph`` names ``posegraph.graph``)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        for name in names:
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name and name != module and not module.startswith(name + "."):
                found.add(name)
    return found


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in edges:
        if v not in index:
            visit(v)
    # A package's __init__ that re-exports its own modules is not a cycle between jobs.
    return [c for c in found if not (len(c) == 2 and c[1].startswith(c[0] + "."))]


def test_the_package_has_no_import_cycle():
    edges = {module: _imported(module, path) for module, path in MODULES.items()}
    assert _cycles(edges) == []


def test_the_import_walk_finds_a_cycle_where_there_is_one():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_modules_and_functions_are_small():
    """No module above 400 lines (benchmark scripts aside), no function above 60, in the
    library and the command line."""
    big, long = [], []
    for path in [*PACKAGE.rglob("*.py"), *(ROOT / "cli").rglob("*.py")]:
        text = path.read_text()
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES and "benchmarks" not in path.parts:
            big.append(f"{path.relative_to(ROOT)}: {lines}")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.name}: {length}")
    assert big == [] and long == []


def test_a_pose_graph_holds_its_data_and_nothing_of_a_solve():
    """After a least-squares solve, covariances and a robust run (each through a smoother, and
    through the one-shot call), the graph's attributes and its pickle hold its data alone."""
    graph = posegraph.read_graph(str(ROOT / "datasets" / "manhattan_small.g2o")).graph
    corrupted, _ = add_false_loops(graph, 0.1, seed=0)
    data = {"group", "_stacks", "equivalences", "_index_of", "_components", "structure_version"}
    for robust in (None, "gnc"):
        smoother = posegraph.Smoother(corrupted)
        smoother.optimize(robust=robust)
        posegraph.marginals(smoother, corrupted.node_ids[:3])
        posegraph.optimize(corrupted, robust=robust)
        assert set(vars(corrupted)) == data
        state = pickle.loads(pickle.dumps(corrupted)).__dict__
        assert set(state) == data
        solver_words = r"solution|result|cache|system|decision|factor|linear|weight"
        assert not [name for name in state if re.search(solver_words, name)]
    restored = pickle.loads(pickle.dumps(corrupted))
    assert restored.values.same_as(corrupted.values)
    assert restored.edges.starts_with(corrupted.edges) and restored.num_edges == corrupted.num_edges


def test_the_one_shot_call_keeps_nothing_for_the_next():
    """``posegraph.optimize`` on a graph optimised before starts afresh (no warm start), where a
    smoother's second call warm-starts."""
    graph = posegraph.PoseGraph(SE2)
    graph.add_nodes([0, 1, 2], SE2.identity((3,)))
    step = SE2.from_xytheta([1.0, 0.0, 0.3])
    measured = np.stack([step.as_matrix(), step.as_matrix(), (step @ step).as_matrix()])
    graph.add_edges([0, 1, 0], [1, 2, 2], measured, np.diag([100.0, 100.0, 400.0]))
    assert posegraph.optimize(graph).summary.initialization == "chordal"
    assert posegraph.optimize(graph).summary.initialization == "chordal"
    smoother = posegraph.Smoother(graph)
    smoother.optimize()
    assert smoother.optimize().summary.initialization == "warm start"


def test_the_architecture_page_names_every_subpackage_and_module():
    page = (ROOT / "docs" / "architecture.md").read_text()
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE)
        if path.name == "__init__.py":
            name = f"posegraph/{relative.parent.as_posix()}/" if relative.parent.parts else None
            if name and f"`{name}`" not in page:
                missing.append(name)
        elif f"`{path.name}`" not in page:
            missing.append(relative.as_posix())
    assert missing == []


def test_the_readme_is_a_guide_of_at_most_2500_words():
    words = len(re.findall(r"\S+", (ROOT / "README.md").read_text()))
    assert 500 < words <= 2500


def test_every_subpackage_is_installed():
    """``pip install .`` installs the packages pyproject.toml lists: every folder of the
    library must be one of them."""
    tomllib = pytest.importorskip("tomllib", reason="tomllib is in Python 3.11 and later")
    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    folders = {_module_name(path) for path in PACKAGE.rglob("__init__.py")}
    assert folders <= listed
