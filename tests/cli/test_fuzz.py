"""A bounded fuzz run in the suite: seeded mutants of every format through the command line's
entry point and the library (``tests/soak/soak.py``, whose longer runs are not part of CI)."""

from __future__ import annotations

import pytest

from ..soak.soak import soak

pytest.importorskip("posegraph_cli")


def test_mutants_of_every_format_keep_the_promises():
    """For about 25 s: each command exits 0 with finite outputs or 2 with one line naming the
    file, and the readers return or raise ``GraphFileError``; no exit 3, hang, leftover
    output or changed input."""
    report = soak(mutants=100_000, seed=20261127, budget=25.0)
    failures = [f"{label}: {outcome}\n{text}" for label, outcome, text in report.failures]
    assert not failures, "\n\n".join(failures[:3])
    assert report.mutants >= 100
    outcomes = {outcome.split(": ", 1)[1] for outcome in report.outcomes}
    assert {"exit 0", "exit 2", "read", "refused"} <= outcomes
