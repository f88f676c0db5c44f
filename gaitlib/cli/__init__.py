"""The ``gaitlib`` command line: one typer app, one thin module per command group."""

from __future__ import annotations

import sys

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
    except KeyboardInterrupt:
        print("gaitlib: interrupted; finished work is saved (train: --resume; collect: rerun to resume)", file=sys.stderr)
        sys.exit(130)
    except typer.Exit as exit_:
        sys.exit(exit_.exit_code)
    except typer.Abort:
        print("gaitlib: aborted", file=sys.stderr)
        sys.exit(1)
    except Exception as error:  # click usage errors arrive here in non-standalone mode
        import click

        if isinstance(error, click.ClickException):
            error.show()
            sys.exit(error.exit_code)
        raise
