"""Live optimisation progress on a terminal, and the Ctrl-C handling that stops cleanly."""

from __future__ import annotations

import signal
import sys

from posegraph.solvers import IterationRecord


class Progress:
    """Prints one line per iteration to stderr when it is a terminal (never when piped); its
    damping column is Levenberg-Marquardt's λ, or the dogleg's trust-region radius with
    ``method`` "dogleg"."""

    def __init__(self, enabled: bool, method: str = "lm") -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.damping_name = "radius" if method == "dogleg" else "lambda"
        self.interrupted = False
        self._previous_handler = None

    def __enter__(self) -> Progress:
        self._previous_handler = signal.signal(signal.SIGINT, self._on_interrupt)
        return self

    def __exit__(self, *exc) -> None:
        signal.signal(signal.SIGINT, self._previous_handler)

    def _on_interrupt(self, signum, frame) -> None:
        self.interrupted = True
        if self.enabled:
            print("interrupted: stopping after this iteration …", file=sys.stderr)

    def __call__(self, record: IterationRecord) -> bool:
        """The solver callback: print, and stop the run once Ctrl-C was pressed. The header
        comes with the first iteration, with a stage column when the run has stages (GNC)."""
        if self.enabled:
            if record.iteration == 1:
                stage = "  stage" if record.stage else ""
                header = f"{'iter':>5} {'error':>16} {self.damping_name:>9} {'step':>9} {'time':>8}{stage}"
                print(header, file=sys.stderr)
            stage = f"  {record.stage}" if record.stage else ""
            mark = "" if record.accepted else "  (rejected)"
            print(
                f"{record.iteration:>5} {record.error:>16.10g} {record.damping:>9.2e} "
                f"{record.step_norm:>9.2e} {record.elapsed:>7.2f}s{stage}{mark}",
                file=sys.stderr,
                flush=True,
            )
        return self.interrupted
