"""The ``gaitlib`` command line: one typer app, one thin module per command group."""

from __future__ import annotations

import sys

import click
import typer

from gaitlib.cli import bench, train, transitions
from gaitlib.errors import GaitlibError

__all__ = ["app", "main"]

app = typer.Typer(
    name="gaitlib",
    help="A library of independently trained quadruped gaits (Unitree A1) and robust switching between them.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
app.command("train")(train.train_command)
app.command("eval")(train.eval_command)
app.command("collect")(transitions.collect_command)
app.command("fit")(transitions.fit_command)
app.add_typer(bench.app, name="bench")


def main() -> None:
    """Console entry point: run the app, turning gaitlib errors and Ctrl-C into one line on stderr."""
    try:
        app(standalone_mode=False)
    except GaitlibError as error:
        print(f"gaitlib: error: {error}", file=sys.stderr)
        sys.exit(2)
    except (KeyboardInterrupt, click.exceptions.Abort):  # click turns Ctrl-C into Abort
        print("gaitlib: interrupted; finished work is saved (train: --resume; collect: rerun to resume)", file=sys.stderr)
        sys.exit(130)
    except click.exceptions.Exit as exit_:
        sys.exit(exit_.exit_code)
    except click.ClickException as error:  # usage errors arrive here in non-standalone mode
        error.show()
        sys.exit(error.exit_code)
    except OSError as error:  # a full disk, a read-only folder: nothing already written is lost (atomic writes)
        where = f" ({error.filename})" if error.filename else ""
        print(f"gaitlib: error: {error.strerror or error}{where}", file=sys.stderr)
        sys.exit(1)
