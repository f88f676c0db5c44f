"""Printing the commands' rich tables: the console they go to, and the two-column tables of the measuring commands
(one measure per row)."""

from __future__ import annotations

__all__ = ["print_measures", "rate_text", "table_console"]

_LOG_WIDTH = 160
"""Columns of a table printed to a file or a pipe (rich's 80 would cut the names of wide tables), characters."""


def table_console():
    """A rich console on standard output, wide enough for any of our tables when that is not a terminal."""
    from rich.console import Console

    console = Console()
    if not console.is_terminal:
        console.width = _LOG_WIDTH
    return console


def print_measures(title: str, rows: list[tuple[str, str]], *, header: tuple[str, str] = ("measure", "value")) -> None:
    """Print ``rows`` of (measure, formatted value) under ``title``, values right-aligned."""
    from rich.table import Table

    table = Table(title=title)
    table.add_column(header[0])
    table.add_column(header[1], justify="right")
    for name, value in rows:
        table.add_row(name, value)
    table_console().print(table)


def rate_text(rate: float, ci95: tuple[float, float], *, digits: int = 2) -> str:
    """A rate in percent with its 95% interval, to ``digits`` decimals."""
    return f"{100 * rate:.{digits}f}% [{100 * ci95[0]:.{digits}f}, {100 * ci95[1]:.{digits}f}]"
