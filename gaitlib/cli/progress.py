"""The rich progress display shared by the long-running commands (train, collect)."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

__all__ = ["job_progress"]


def job_progress(console: Console, label: str) -> Progress:
    """A bar with done/total, a ``status`` text field, elapsed time and ETA; tasks must set ``status``. Drawn on a
    terminal only: a log gets the commands' own lines, so that a run refused while it sets up writes one line."""
    return Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        disable=not console.is_terminal,
    )
