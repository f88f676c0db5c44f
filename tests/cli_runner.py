"""Running the ``gaitlib`` command line as a user does: a fresh process, its exit code, stdout and stderr."""

from __future__ import annotations

import subprocess
import sys


def gaitlib(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``gaitlib ARGS...`` in a child process (the installed entry point's code path)."""
    return subprocess.run(
        [sys.executable, "-c", "from gaitlib.cli import main; main()", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )
