"""The ``gaitlib`` command line: one typer app, one thin module per command group."""

from __future__ import annotations

import errno
import signal
import sys
from importlib.metadata import version

import typer

from gaitlib.cli import (
    drive,
    evaluate,
    gaits,
    library,
    mirror,
    routes,
    survival,
    switching,
    throughput,
    train,
    transitions,
)
from gaitlib.errors import GaitlibError

__all__ = ["app", "main"]

app = typer.Typer(
    name="gaitlib",
    help="A library of independently trained quadruped gaits (Unitree A1) and robust switching between them.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _print_version(show: bool) -> None:
    """``--version``: one line, the version in gaitlib's package metadata, and exit."""
    if show:
        print(f"gaitlib {version('gaitlib')}")
        raise typer.Exit()


@app.callback()
def _options(
    _version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="Print gaitlib's version and exit."
    ),
) -> None:
    """The options of ``gaitlib`` itself, given before a command (its help is the app's)."""


app.command("train")(train.train_command)
app.command("mirror")(mirror.mirror_command)
app.command("eval")(evaluate.eval_command)
app.command("library")(library.library_command)
app.command("gaits")(gaits.gaits_command)
app.command("collect")(transitions.collect_command)
app.command("fit")(transitions.fit_command)
app.command("states")(transitions.states_command)
app.command("map")(transitions.map_command)
app.command("benchmark")(switching.benchmark_command)
app.command("run")(switching.run_command)
app.command("routes")(routes.routes_command)
app.command("drive")(drive.drive_command)
app.add_typer(throughput.app, name="throughput")
app.add_typer(survival.app, name="survival")


def main() -> None:
    """Console entry point: run the app, turning gaitlib errors, OS errors and Ctrl-C into one line on stderr."""
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops a long job as Ctrl-C does: finished work is kept
    try:
        code = app(standalone_mode=False)  # typer turns Ctrl-C inside a command into exit code 130
    except GaitlibError as error:
        print(f"gaitlib: error: {error}", file=sys.stderr)
        sys.exit(2)
    except (KeyboardInterrupt, typer.Abort):
        code = 130
    except typer.Exit as exit_:
        code = exit_.exit_code
    except typer.TyperException as error:  # usage errors (typer's own click exceptions) in non-standalone mode
        show = getattr(error, "show", None)
        if show is not None:
            show()
        else:
            print(f"gaitlib: error: {error}", file=sys.stderr)
        sys.exit(getattr(error, "exit_code", 2))
    except OSError as error:  # a full disk, a read-only folder: nothing already written is lost (atomic writes)
        print(f"gaitlib: error: {_os_error(error)}", file=sys.stderr)
        sys.exit(1)
    if code == 130:
        print(
            "gaitlib: interrupted; finished work is saved (train: --resume; collect: rerun to resume)", file=sys.stderr
        )
    sys.exit(code if isinstance(code, int) else 0)


def _os_error(error: OSError) -> str:
    """One line for an ``OSError``; a full disk says what is kept and how to go on."""
    where = f" ({error.filename})" if error.filename else ""
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        return (f"no space left on the device writing {error.filename or 'a file'}; every file written before is "
                "kept whole (writes are atomic): free space and run the command again (train: with --resume)")
    return f"{error.strerror or error}{where}"


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
