"""The markdown tables the benchmark scripts print."""

from __future__ import annotations


class MarkdownTable:
    """A markdown table built row by row from cells joined by " | ". With ``echo`` every line is
    printed as it is added, so that a long benchmark shows its rows as they come."""

    def __init__(self, header: str, echo: bool = False) -> None:
        self.echo = echo
        self.lines: list[str] = []
        self.add(header)
        self.add(" | ".join(["---"] * (header.count("|") + 1)))

    def add(self, row: str) -> None:
        """Append a row given as "cell | cell | …" (without the outer bars)."""
        line = f"| {row} |"
        self.lines.append(line)
        if self.echo:
            print(line, flush=True)

    def add_present(self, rows) -> None:
        """Append each row of an iterable, leaving out the None ones (a graph not on this
        machine)."""
        for row in rows:
            if row is not None:
                self.add(row)

    def __str__(self) -> str:
        return "\n".join(self.lines)
