"""Soak test of the promises on bad input: seeded mutants of small valid files of every format
(g2o, TORO, both Sim3 dialects, mixed SE3 and Sim3, TUM, KITTI, covariances) through the command
line's entry point and the library, with the count of each outcome.

    python -m tests.soak.soak --mutants 5000 --seed 1

(from the project's root; not run by the suite, whose ``tests/cli/test_fuzz.py`` runs the same
mutants for about a minute).

A run passes when no mutant breaks a promise: each command exits 0 (or 1, not converged) with
outputs whose numbers are all finite, or exits 2 with one line on stderr naming the file; never
3, an uncaught exception, a hang, an output left behind after a failure, or an input changed.
The library's readers return or raise ``GraphFileError`` naming the file.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import dataclasses
import hashlib
import io
import json
import random
import shutil
import signal
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from posegraph_cli.main import main as posegraph_main

from posegraph.io import GraphFileError, ReadOptions, load_graph, read_graph
from posegraph.io.covariances import read_covariances
from posegraph.io.trajectories import read_trajectory

INFO_SE2 = "100 0 0 100 0 1000"
INFO_SE3 = "100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400"
INFO_SIM3 = "100 0 0 0 0 0 0 100 0 0 0 0 0 100 0 0 0 0 400 0 0 0 400 0 0 400 0 50"
INFO_TORO2 = "100 0 100 1000 0 0"
INFO_TORO3 = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1"

GRAPH_FILES = {
    "se2.g2o": f"""VERTEX_SE2 0 0 0 0
# a comment holding a form feed \f and U+2028 \u2028 VERTEX_SE2 9 x, all of one line
VERTEX_SE2 1 1 0 0.1
VERTEX_SE2 2 2 0.1 0.2
VERTEX_SE2 3 2 1 1.6
EDGE_SE2 0 1 1 0 0.1 {INFO_SE2}
EDGE_SE2 1 2 1 0.1 0.1 {INFO_SE2}
EDGE_SE2 2 3 1 0 1.5 {INFO_SE2}
EDGE_SE2 3 0 2 1 1.6 100 1 0 100 0 1000
# posegraph:rejected EDGE_SE2 0 2 5 5 1 {INFO_SE2}
EDGE_PRIOR_SE2 0 0 0 0 10 0 0 10 0 10
FIX 0
""",
    "se3.g2o": f"""VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0.0998 0.995
VERTEX_SE3:QUAT 2 2 0.1 0 0 0 0.2 0.98
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SE3:QUAT 1 2 1 0.1 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SE3:QUAT 2 0 -2 0 0 0 0 -0.2 0.98 {INFO_SE3}
PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1
EDGE_SE3_PRIOR 1 0 1 0 0 0 0 0.1 0.995 {INFO_SE3}
""",
    "sim3a.g2o": f"""VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1
VERTEX_SIM3:EXPMAP 1 0 0 0.05 0.999 -1 0 0 0.9
VERTEX_SIM3:EXPMAP 2 0 0 0.1 0.995 -2 0.1 0 0.8
EDGE_SIM3:EXPMAP 0 1 0 0 0.05 0.999 1 0 0 1.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 1 2 0 0 0.05 0.999 1 0.1 0 1.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 2 0 0 0 -0.1 0.995 2 0 0 1.2 {INFO_SIM3}
""",
    "sim3b.g2o": f"""VERTEX_SIM3:EXPMAP 0 0 0 0 0 0 0 0 500 500 320 240
VERTEX_SIM3:EXPMAP 1 1 0 0 0 0 0.1 0.1 500 500 320 240
VERTEX_SIM3:EXPMAP 2 2 0 0 0 0 0.2 0.2 500 500 320 240
EDGE_SIM3:EXPMAP 0 1 1 0 0 0 0 0.1 0.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 1 2 1 0 0 0 0 0.1 0.1 {INFO_SIM3}
EDGE_SIM3:EXPMAP 2 0 -2 0 0 0 0 -0.2 -0.2 {INFO_SIM3}
""",
    "mixed.g2o": f"""VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0.0998 0.995
VERTEX_SE3:QUAT 2 2 0.1 0 0 0 0.2 0.98
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SE3:QUAT 1 2 1 0.1 0 0 0 0.1 0.995 {INFO_SE3}
EDGE_SIM3:EXPMAP 2 0 0 0 -0.1 0.995 2 0 0 1.2 {INFO_SIM3}
""",
    "toro2.graph": f"""VERTEX2 0 0 0 0
VERTEX2 1 1 0 0
VERTEX2 2 2 0 0
EDGE2 0 1 1 0 0 {INFO_TORO2}
EDGE2 1 2 1 0 0 {INFO_TORO2}
EDGE2 2 0 -2 0 0 {INFO_TORO2}
EQUIV 0 0
""",
    "toro3.graph": f"""VERTEX3 0 0 0 0 0 0 0
VERTEX3 1 1 0 0 0 0 0
EDGE3 0 1 1 0 0 0 0 0.1 {INFO_TORO3}
EDGE3 1 0 -1 0 0 0 0 -0.1 {INFO_TORO3}
""",
}
"""Small valid graph files of every tag and dialect (a comment holds characters that
``str.splitlines`` would end a line at; a line is marked rejected)."""

TRAJECTORY_FILES = {
    "poses.tum": """# timestamp tx ty tz qx qy qz qw \v (a vertical tab in a comment)
0.0 0 0 0 0 0 0 1
0.1 1 0 0 0 0 0.0998 0.995
0.2 2 0.1 0 0 0 0.2 0.98
0.3 3 0.3 0.1 0 0 0.3 0.954
""",
    "poses.kitti": """1 0 0 0 0 1 0 0 0 0 1 0
0.995 -0.0998 0 1 0.0998 0.995 0 0 0 0 1 0
0.98 -0.199 0 2 0.199 0.98 0 0.1 0 0 1 0
0.955 -0.296 0 3 0.296 0.955 0 0.3 0 0 1 0.1
""",
}
"""Small valid trajectories (the KITTI rotations about z, rounded as such files are)."""

COVARIANCE_FILES = {
    "covariances.txt": """# posegraph marginal covariances, SE2: tangent delta = (x, y, theta)
# id x*x x*y x*theta y*y y*theta theta*theta
0 0 0 0 0 0 0
1 0.01 0.001 0 0.02 0.001 0.001
2 0.03 0.002 0.001 0.04 0.002 0.002
""",
}

ODD_TOKENS = [
    "nan", "inf", "-inf", "1e400", "-1e400", "1e308", "1e-320", "1e-300", "1e160", "-0", "0",
    "-1", "1.5", "2", "7", "99999999999999999999", "9007199254740993", "0x10", "1,5", "1_0",
    "abc", "#", "١", "３", "1\u00a02", "\f", "\v", "\x85", "\u2028", "1e-9", "355", "800",
]  # fmt: skip
"""Tokens that mutants put in: non-finite and overflowing numbers, ids beyond 2⁵³, numbers in
other syntaxes (Python's or other scripts'), and characters that other tools end lines at."""


def mutate(text: str, rng: random.Random) -> str:
    """``text`` with one to three mutations: a token replaced, dropped or inserted, a line
    duplicated, deleted or swapped with another, or a tag replaced by another file's."""
    lines = [line.split(" ") for line in text.splitlines()]
    tags = sorted({line.split()[0] for files in SEEDS.values() for line in files.splitlines()})
    for _ in range(rng.randint(1, 3)):
        if not lines:
            lines.append([])
        k = rng.randrange(len(lines))
        tokens = lines[k]
        position = rng.randint(0, len(tokens))
        kind = rng.choice(["replace", "drop", "insert", "duplicate", "delete", "swap", "tag"])
        if kind == "insert" or (kind in ("replace", "drop") and position == len(tokens)):
            tokens.insert(position, rng.choice(ODD_TOKENS))
        elif kind == "replace":
            tokens[position] = rng.choice(ODD_TOKENS)
        elif kind == "drop":
            del tokens[position]
        elif kind == "duplicate":
            lines.insert(rng.randint(0, len(lines)), list(tokens))
        elif kind == "delete":
            del lines[k]
        elif kind == "swap":
            other = rng.randrange(len(lines))
            lines[k], lines[other] = lines[other], lines[k]
        elif tokens:
            tokens[0] = rng.choice(tags)
    return "".join(" ".join(tokens) + "\n" for tokens in lines)


SEEDS = {**GRAPH_FILES, **TRAJECTORY_FILES, **COVARIANCE_FILES}


class Hang(BaseException):
    """A run that took longer than its limit (not an ``Exception``: nothing catches it)."""


@contextlib.contextmanager
def _time_limit(seconds: int) -> Iterator[None]:
    def expire(signum, frame):
        raise Hang

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _digest(folder: Path) -> dict[str, str]:
    return {path.name: hashlib.sha256(path.read_bytes()).hexdigest() for path in folder.iterdir()}


def _all_finite(path: Path) -> bool:
    """Whether every number of an output is finite (comment lines and tags left out)."""
    for line in path.read_text().split("\n"):
        for token in line.partition("#")[0].split():
            try:
                number = float(token)
            except ValueError:
                continue
            if not np.isfinite(number):
                return False
    return True


def _cli(argv: list[str]) -> tuple[int, str, str]:
    """The ``posegraph`` command run in this process: (exit code, stdout, stderr)."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = posegraph_main(argv)
    return code, stdout.getvalue(), stderr.getvalue()


def _named_line(message: str, source: Path) -> int | None:
    """The line number of an error "posegraph: error: FILE:LINE: …" about ``source``."""
    rest = message.removeprefix(f"posegraph: error: {source}:")
    number = rest.split(":", 1)[0]
    return int(number) if rest != message and number.isdigit() else None


def _broken_promise(folder, source, code, stdout, stderr, before, after, outputs) -> str | None:
    """Which promise a command's run broke, if any."""
    if any(after.get(name) != digest for name, digest in before.items()):
        return "an input changed"
    if code == 2:
        lines = stderr.splitlines()
        if len(lines) != 1 or not lines[0].startswith("posegraph: error: "):
            return f"exit 2 with {len(lines)} lines on stderr"
        if set(after) != set(before):
            return "an output left behind after a failure"
        if str(folder) not in lines[0] and "--" not in lines[0]:
            return "the error names no file"
        line = _named_line(lines[0], source)
        if line is not None and not 1 <= line <= source.read_text().count("\n") + 1:
            return f"the error names line {line}, which the file does not have"
        return None
    if code not in (0, 1):
        return f"exit {code}: {stderr.strip()[:200]}"
    missing = [path.name for path in outputs if not path.exists()]
    if missing:
        return f"exit {code} without {missing[0]}"
    if not all(_all_finite(path) for path in outputs):
        return "a non-finite number in an output"
    document = json.loads(stdout)
    reports = [document, document.get("summary", {})]
    errors = [r[key] for r in reports for key in ("initial_error", "final_error") if key in r]
    if not all(isinstance(error, float | int) for error in errors):  # null: NaN or ∞
        return f"exit {code} with an error that is not finite"
    return None


def _command_outcome(folder: Path, source: Path, argv: list[str], outputs: list[Path]) -> str:
    """The outcome of one command (run with ``--json``) on ``source``: "exit 0", "exit 1",
    "exit 2", or a broken promise ("FAIL: …")."""
    before = _digest(folder)
    code, stdout, stderr = _cli([*argv, "--json"])
    after = _digest(folder)
    problem = _broken_promise(folder, source, code, stdout, stderr, before, after, outputs)
    for path in outputs:
        path.unlink(missing_ok=True)
    return f"FAIL: {problem}" if problem else f"exit {code}"


def _library_outcome(source: Path, read: Callable[[str], object]) -> str:
    try:
        read(str(source))
    except GraphFileError as error:
        if not str(error).startswith(str(source)):
            return "FAIL: library error names no file"
        return "refused"
    except Exception as error:  # noqa: BLE001 - what a soak test is for
        return f"FAIL: library raised {type(error).__name__}: {str(error)[:200]}"
    return "read"


def _graph_runs(folder: Path, source: Path) -> list[tuple[str, Callable[[], str]]]:
    out, tum, cov = folder / "out.g2o", folder / "out.tum", folder / "cov.txt"
    lenient = ReadOptions(lenient=True)
    return [
        ("info", lambda: _command_outcome(folder, source, ["info", str(source)], [])),
        (
            "optimize",
            lambda: _command_outcome(
                folder,
                source,
                ["optimize", str(source), "-o", str(out), "--covariances", str(cov)],
                [out, cov],
            ),
        ),
        (
            "optimize --lenient",
            lambda: _command_outcome(
                folder, source, ["optimize", str(source), "--lenient", "-o", str(out)], [out]
            ),
        ),
        (
            "convert",
            lambda: _command_outcome(folder, source, ["convert", str(source), str(tum)], [tum]),
        ),
        ("read_graph", lambda: _library_outcome(source, read_graph)),
        ("load_graph lenient", lambda: _library_outcome(source, lambda p: load_graph(p, lenient))),
    ]


def _trajectory_runs(folder: Path, source: Path) -> list[tuple[str, Callable[[], str]]]:
    truth = folder / f"truth{source.suffix}"
    truth.write_text(TRAJECTORY_FILES[f"poses{source.suffix}"])
    file_format = source.suffix[1:]
    return [
        ("eval", lambda: _command_outcome(folder, source, ["eval", str(source), str(truth)], [])),
        (
            "read_trajectory",
            lambda: _library_outcome(source, lambda p: read_trajectory(p, file_format)),
        ),
    ]


def _covariance_runs(folder: Path, source: Path) -> list[tuple[str, Callable[[], str]]]:
    return [("read_covariances", lambda: _library_outcome(source, read_covariances))]


@dataclasses.dataclass
class SoakReport:
    """Outcomes per run ("optimize: exit 2" → count) and the failures, with their mutants."""

    mutants: int = 0
    outcomes: collections.Counter = dataclasses.field(default_factory=collections.Counter)
    failures: list[tuple[str, str, str]] = dataclasses.field(default_factory=list)
    """(run, outcome, the mutant's text)."""


def soak(mutants: int, seed: int, budget: float | None = None, limit: int = 20) -> SoakReport:
    """Run ``mutants`` mutants (or as many as ``budget`` seconds allow) of the seed files
    through every run of their kind; each run is stopped as a hang after ``limit`` seconds."""
    rng = random.Random(seed)
    report = SoakReport()
    start = time.perf_counter()
    names = sorted(SEEDS)
    with tempfile.TemporaryDirectory() as workdir:
        for _ in range(mutants):
            if budget is not None and time.perf_counter() - start > budget:
                break
            name = rng.choice(names)
            folder = Path(workdir) / f"m{report.mutants}"
            folder.mkdir()
            source = folder / name
            text = mutate(SEEDS[name], rng)
            source.write_text(text)
            kind = _graph_runs if name in GRAPH_FILES else _trajectory_runs
            kind = _covariance_runs if name in COVARIANCE_FILES else kind
            for label, run in kind(folder, source):
                try:
                    with _time_limit(limit):
                        outcome = run()
                except Hang:
                    outcome = "FAIL: hang"
                report.outcomes[f"{label}: {outcome}"] += 1
                if outcome.startswith("FAIL"):
                    report.failures.append((label, outcome, text))
            shutil.rmtree(folder)
            report.mutants += 1
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mutants", type=int, default=5000)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    report = soak(args.mutants, args.seed)
    print(f"{report.mutants} mutants, seed {args.seed}")
    for outcome, count in sorted(report.outcomes.items()):
        print(f"{count:>7}  {outcome}")
    for label, outcome, text in report.failures[:10]:
        print(f"\n{label}: {outcome}\n{text}")
    print(f"\n{len(report.failures)} failure(s)")
    return 1 if report.failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
