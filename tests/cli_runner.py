"""Running the ``gaitlib`` command line as a user does: its exit code, stdout and stderr.

:func:`gaitlib` starts a fresh process (the installed entry point's code path, C-level output included): every
command that simulates or writes runs that way in at least one test. :func:`gaitlib_quick` calls the same entry
point, :func:`gaitlib.cli.main`, inside the test process, where a new interpreter would spend seconds importing
torch: for refusals that happen before any work, commands that only read, and a test's further calls of a command
already run in a fresh process elsewhere.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys


def gaitlib(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``gaitlib ARGS...`` in a child process."""
    return subprocess.run(
        [sys.executable, "-c", "from gaitlib.cli import main; main()", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def gaitlib_quick(*args: str) -> subprocess.CompletedProcess[str]:
    """``gaitlib ARGS...`` through :func:`gaitlib.cli.main` in this process, stdout and stderr captured."""
    from gaitlib.cli import main

    out, err = io.StringIO(), io.StringIO()
    argv = sys.argv
    sys.argv = ["gaitlib", *args]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main()
                code = 0
            except SystemExit as exit_:
                code = exit_.code if isinstance(exit_.code, int) else 1
    finally:
        sys.argv = argv
    return subprocess.CompletedProcess(["gaitlib", *args], code, out.getvalue(), err.getvalue())
