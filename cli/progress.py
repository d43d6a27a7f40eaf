"""Live progress of a command on stderr, and the Ctrl-C handling that stops a solve cleanly.

One line per stage (reading, initialising, iterating, and each solve of a robust run), updated
in place on a terminal (rich); where stderr is not a terminal (a log), each solve's line is
written once, when it ends, and the stages without iterations are left out. ``--quiet`` and
``--json`` show none.
"""

from __future__ import annotations

import contextlib
import re
import signal
import sys
import time
from collections.abc import Iterator

from posegraph.solvers import IterationRecord

LEAST_SQUARES = "½Σ rᵀΩr"
WEIGHTED = "½Σ w rᵀΩr"
"""The cost a solve minimises, as its line labels it: least squares, or a robust run's solve
with fixed weights (each GNC stage's, or one of its least-squares solves over a kept set)."""


_ROUND = re.compile(r"(?P<name>.+) round (?P<round>\d+) \((?P<start>.+)\)")
"""A GNC round's stage label: "gnc round 3 (chordal)", "gnc round 12 (warm)"."""


class Progress:
    """A command's progress display (module docstring), and the solver's callback: it updates
    the line of the record's stage and, once Ctrl-C was pressed inside ``interruptible``, asks
    the solve to stop. ``limit`` is the iteration limit shown; ``cost`` labels the cost of
    records without a stage (``LEAST_SQUARES``, or a robust kernel's ½Σρ); the damping column
    is Levenberg-Marquardt's λ, or the dogleg's trust-region radius with ``method`` "dogleg"."""

    def __init__(
        self,
        enabled: bool,
        method: str = "lm",
        limit: int | None = None,
        cost: str = LEAST_SQUARES,
    ) -> None:
        self.enabled = enabled
        self.live = enabled and sys.stderr.isatty()
        self.damping_name = "radius" if method == "dogleg" else "λ"
        self.limit = limit
        self.cost = cost
        self.interrupted = False
        self._display = None  # rich's Progress, on a terminal (``live.display``)
        self._task = None
        self._stage: str | None = None
        self._count = 0
        self._begun = 0.0
        self._last: IterationRecord | None = None
        self._round: str | None = None

    def __enter__(self) -> Progress:
        if self.live:
            from .live import display  # rich, imported only for a terminal

            self._display = display()
            self._display.start()
        return self

    def __exit__(self, error_type, error, trace) -> None:
        if error_type is None:
            self.end()
        if self._display is not None:
            self._display.stop()

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """A stage without iterations (reading a file): its line while the block runs."""
        self.begin(name)
        yield
        self.end()

    def begin(self, name: str) -> None:
        """End the current stage and start ``name``'s line."""
        self.end()
        self._stage, self._count, self._last, self._round = name, 0, None, None
        self._begun = time.perf_counter()
        if self._display is not None:
            self._task = self._display.add_task(name, total=None, status="")

    def end(self) -> None:
        """End the current stage: its line stays (on a terminal) or is written (elsewhere)."""
        if self._stage is None:
            return
        if self._display is not None:
            self._display.update(self._task, total=1, completed=1, status=self._status())
            self._display.stop_task(self._task)
        elif self.enabled and self._last is not None:
            seconds = time.perf_counter() - self._begun
            print(f"{self._stage:<22} {seconds:6.2f} s {self._status()}", file=sys.stderr)
        self._stage = None

    def _status(self) -> str:
        """The stage's iterations, its cost and damping after the last, or "" before any."""
        record = self._last
        if record is None:
            return ""
        limit = f"/{self.limit}" if self.limit and not record.stage else ""
        round_ = f"round {self._round} · " if self._round else ""
        cost = WEIGHTED if record.stage else self.cost
        rejected = " (rejected)" if not record.accepted else ""
        return (
            f"{round_}it {self._count}{limit} · {cost} {record.error:.7g} · "
            f"{self.damping_name} {record.damping:.0e}{rejected}"
        )

    @contextlib.contextmanager
    def interruptible(self) -> Iterator[None]:
        """Within the block, Ctrl-C stops the solve after its iteration, not the program."""
        previous = signal.signal(signal.SIGINT, self._on_interrupt)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    def _on_interrupt(self, signum, frame) -> None:
        self.interrupted = True
        if self.enabled:
            message = "interrupted: stopping after this iteration …"
            if self._display is not None:
                self._display.console.print(message)
            else:
                print(message, file=sys.stderr)

    def __call__(self, record: IterationRecord) -> bool:
        """The solver callback: the record's stage line, updated; True once Ctrl-C was
        pressed. GNC's rounds share a line per start ("gnc (chordal)", "gnc (warm)"), which
        shows the round."""
        match = _ROUND.fullmatch(record.stage)
        stage = f"{match['name']} ({match['start']})" if match else record.stage or "iterating"
        if stage != self._stage:
            self.begin(stage)
        if match and match["round"] != self._round:
            self._round, self._count = match["round"], 0
        self._count += 1
        self._last = record
        if self._display is not None:
            self._display.update(self._task, status=self._status())
        return self.interrupted
