"""The guard on the command line: its options (on by default for the commands that run one robot on the
meta-controller, ``gaitlib run`` and ``drive``; asked for with ``--guard`` in ``benchmark`` and ``eval``), whether
it is on, and its catches printed."""

from __future__ import annotations

import typer

from gaitlib.values import number_text

__all__ = ["choose_guard", "guard_margin_option", "guard_option", "opt_in_guard_option", "print_guard"]


def guard_option():
    """``--guard/--no-guard``, on by default."""
    return typer.Option(True, "--guard/--no-guard", help="Let the guard catch the robot where another gait offers "
                        "clearly more than staying (docs/switching.md, \"The guard\"); a library without a survival "
                        "estimate runs unguarded and says so.")


def opt_in_guard_option(help: str):
    """``--guard``, off by default (``help`` says what it guards); ``--guard-margin`` turns it on too."""
    return typer.Option(False, "--guard", help=help)


def guard_margin_option(*, opt_in: bool = False):
    """``--guard-margin``: the guard's margin instead of the library's; ``opt_in`` for a command whose guard is off
    unless asked for (:func:`opt_in_guard_option`)."""
    from gaitlib.cli.options import bounded
    from gaitlib.values import GUARD_MARGIN

    if opt_in:
        return bounded(None, "--guard-margin", help="With --guard: the guard's margin (default: the one chosen with "
                       "the survival estimate);", bounds=GUARD_MARGIN)
    return bounded(None, "--guard-margin", help="The guard's margin (default: the one chosen with the library's "
                   "survival estimate);", bounds=GUARD_MARGIN)


def choose_guard(setup, *, on: bool, margin: float | None, quiet: bool):
    """The library's guard and ``None``, or ``None`` and why the robot runs unguarded (said on stdout unless
    ``quiet``): ``--no-guard``, or a library without a (fresh) survival estimate. Refused in one line, before any
    work: ``--guard-margin`` with ``--no-guard`` (it would change nothing), and a damaged estimate (never run
    around as if there were none)."""
    from gaitlib.cli.options import OptionError
    from gaitlib.errors import GaitlibError
    from gaitlib.strategies.survival import SurvivalFileError

    if not on and margin is not None:
        raise OptionError("--guard-margin has no effect with --no-guard (the robot runs unguarded): leave it out")
    guarding, unguarded = None, None if on else "unguarded (--no-guard)"
    if on:
        try:
            guarding = setup.guard(margin=margin)
        except SurvivalFileError:
            raise
        except GaitlibError as why:  # a library fitted before the guard existed, or a stale estimate
            unguarded = f"unguarded: {why}"
    if unguarded and not quiet:
        print(unguarded)
    return guarding, unguarded


def print_guard(report: dict, guarding, trace) -> None:
    """Each catch of a guard report (:meth:`~gaitlib.meta.episode.RunTrace.guard_report`), and the guard's
    settings and count of catches when it was on."""
    for catch in report["catches"]:
        back = "not yet" if catch["back_after_s"] is None else f"after {catch['back_after_s']:.2f} s"
        print(f"guard caught {catch['from']} -> {catch['to']} at {catch['time_s']:.2f} s (staying {catch['stay']:.3f}, "
              f"switching {catch['offer']:.3f}); {catch['requested']} ran again {back}")
    if guarding is not None:
        print(f"guard on (margin {number_text(guarding.margin)}, horizon {number_text(guarding.horizon_s)} s): "
              f"{len(trace.catches)} catch(es)")
