"""Write the command-line reference, ``docs/cli.md``, from the ``gaitlib`` typer app itself, or check it.

    python -m benchmarks.cli_doc            # rewrite docs/cli.md
    python -m benchmarks.cli_doc --check    # exit 1 if docs/cli.md differs from what the app makes

Every command and subcommand, its usage, its help's first paragraph and a table of its options (flag, metavar,
default, help), in the app's own order; ``tests/test_docs.py`` runs the check.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Iterator, Sequence
from pathlib import Path

import typer

__all__ = ["CLI_DOC", "commands", "main", "render"]

ROOT = Path(__file__).resolve().parents[1]
CLI_DOC = ROOT / "docs" / "cli.md"
"""The reference page."""


def commands(group: object | None = None, prefix: str = "gaitlib") -> Iterator[tuple[str, object]]:
    """Every leaf command of the app (``gaitlib train``, ``gaitlib survival fit``, ...) in the app's order, as the
    click commands typer builds (typer carries its own click: groups are told by their ``commands``)."""
    if group is None:
        from gaitlib.cli import app

        group = typer.main.get_command(app)
    for name, command in group.commands.items():
        if hasattr(command, "commands"):
            yield from commands(command, f"{prefix} {name}")
        else:
            yield f"{prefix} {name}", command


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _section(name: str, command) -> str:
    ctx = command.make_context(name, [], resilient_parsing=True)
    usage = " ".join(command.collect_usage_pieces(ctx))
    help_text = (command.help or "").strip().split("\n\n")[0]
    lines = [f"## `{name}`", "", f"```text\n{name} {usage}\n```", "", " ".join(help_text.split()), ""]
    rows = []
    for param in command.params:
        if param.hidden:
            continue
        if param.param_type_name == "argument":
            rows.append(f"| `{' '.join(param.get_usage_pieces(ctx))}` | the argument{_help(param.help)} |")
            continue
        record = param.get_help_record(ctx)  # what --help prints: the flags with their value, the help with its default
        if record is not None:
            flags = " / ".join(f"`{o}`" for o in [*param.opts, *param.secondary_opts])
            rows.append(f"| {flags} | {_cell(record[1])} |")
    if rows:
        lines += ["| option | what it does |", "|---|---|", *rows, ""]
    return "\n".join(lines)


def _help(text: str | None) -> str:
    return f": {_cell(text)}" if text else ""


def render() -> str:
    """The whole page."""
    found = list(commands())
    intro = ("Made from the `gaitlib` app itself by `python -m benchmarks.cli_doc` (the tests check it is current); "
             "`gaitlib COMMAND --help` prints the same. Every command that simulates takes "
             "`--backend auto|mujoco|newton`; every numeric option states its range and unit, and a value outside it "
             "is refused in one line.")
    head = ["# Command-line reference", "", textwrap.fill(intro, 120, break_on_hyphens=False), "",
            *[f"- [`{name}`](#{name.replace(' ', '-')})" for name, _ in found], ""]
    return "\n".join(head + [_section(name, command) for name, command in found]).rstrip("\n") + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cli_doc", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if docs/cli.md is not current")
    args = parser.parse_args(argv)
    made = render()
    current = CLI_DOC.read_text(encoding="utf-8") if CLI_DOC.exists() else None
    if args.check:
        if current != made:
            print("docs/cli.md differs from the app; python -m benchmarks.cli_doc rewrites it", file=sys.stderr)
            return 1
        print("docs/cli.md: current")
        return 0
    if current != made:
        CLI_DOC.write_text(made, encoding="utf-8")
    print(f"docs/cli.md: {'rewritten' if current != made else 'up to date'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
