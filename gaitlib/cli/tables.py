"""The two-column rich tables the measuring commands print (one measure per row)."""

from __future__ import annotations

__all__ = ["print_measures"]


def print_measures(title: str, rows: list[tuple[str, str]], *, header: tuple[str, str] = ("measure", "value")) -> None:
    """Print ``rows`` of (measure, formatted value) under ``title``, values right-aligned."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    table.add_column(header[0])
    table.add_column(header[1], justify="right")
    for name, value in rows:
        table.add_row(name, value)
    Console().print(table)
