"""Exit codes and the single-line error report of the ``posegraph`` command."""

from __future__ import annotations

import sys

EXIT_OK = 0
EXIT_NOT_CONVERGED = 1
EXIT_BAD_INPUT = 2


class UsageError(Exception):
    """Bad arguments or a refused action; reported as one line, exit code 2, that starts
    with ``path`` when it is about one file."""

    def __init__(self, message: str, path: str | None = None) -> None:
        self.path, self.message = path, message
        super().__init__(f"{path}: {message}" if path else message)


def report(message: str) -> None:
    print(f"posegraph: error: {message}", file=sys.stderr)


def warn(message: str) -> None:
    """A finding that does not stop the command, as one line on stderr."""
    print(f"posegraph: warning: {message}", file=sys.stderr)
