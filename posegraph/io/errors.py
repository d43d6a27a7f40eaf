"""The error every reader raises for bad input: it names the file, the line and the problem."""

from __future__ import annotations


class GraphFileError(ValueError):
    """A problem in an input file, reported as ``file:line: message``."""

    def __init__(self, path: str, line: int | None, message: str) -> None:
        self.path, self.line, self.message = str(path), line, message
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")
