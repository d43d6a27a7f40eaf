"""The terminal display of ``progress.Progress`` (rich): one row per stage, with a spinner that
becomes a tick when the stage ends, its name, its seconds, and its status."""

from __future__ import annotations

from rich.console import Console
from rich.progress import Progress, ProgressColumn, SpinnerColumn, Task, TextColumn
from rich.table import Column
from rich.text import Text

NAME_WIDTH = 24
"""The width of a stage's name on the terminal."""


class _Seconds(ProgressColumn):
    """A stage's time so far, in seconds (stages are short: h:mm:ss would show 0:00:00)."""

    def __init__(self) -> None:
        super().__init__(table_column=Column(width=8, no_wrap=True))

    def render(self, task: Task) -> Text:
        return Text(f"{task.elapsed or 0.0:6.2f} s", style="progress.elapsed")


def display() -> Progress:
    """A rich progress display on stderr; its tasks carry a ``status`` field, cut to the
    terminal's width (a longer line would make rich drop the ticks)."""
    console = Console(stderr=True)
    status_width = max(console.width - NAME_WIDTH - 13, 10)  # the tick, seconds and gaps
    return Progress(
        SpinnerColumn(finished_text="✓", table_column=Column(width=1, no_wrap=True)),
        TextColumn(
            "{task.description}",
            table_column=Column(width=NAME_WIDTH, no_wrap=True, overflow="ellipsis"),
        ),
        _Seconds(),
        TextColumn(
            "{task.fields[status]}",
            table_column=Column(max_width=status_width, no_wrap=True, overflow="ellipsis"),
        ),
        console=console,
    )
