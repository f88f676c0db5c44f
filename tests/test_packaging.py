"""The package's layers as an import-linter contract, and an upward import breaking it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from conftest import REPO

LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
"""import-linter's command, installed beside this interpreter (the ``test`` extra)."""


def lint_imports(root: Path) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` in ``root``: its ``gaitlib`` package against the contracts of its ``pyproject.toml``."""
    env = os.environ | {"PYTHONPATH": str(root)}
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache"],
        cwd=root, env=env, capture_output=True, text=True, timeout=120,
    )


def test_every_import_points_down_the_layers() -> None:
    linted = lint_imports(REPO)
    assert linted.returncode == 0, linted.stdout + linted.stderr
    assert "Contracts: 1 kept, 0 broken." in linted.stdout


def test_an_upward_import_breaks_the_layers_contract(tmp_path) -> None:
    shutil.copytree(REPO / "gaitlib", tmp_path / "gaitlib", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy2(REPO / "pyproject.toml", tmp_path)
    with (tmp_path / "gaitlib" / "library" / "layout.py").open("a") as module:
        module.write("\nfrom gaitlib.meta import controller  # the library layer reaching up to the meta-controller\n")
    linted = lint_imports(tmp_path)
    assert linted.returncode == 1, linted.stdout + linted.stderr
    assert "Contracts: 0 kept, 1 broken." in linted.stdout
    assert "gaitlib.library is not allowed to import gaitlib.meta" in linted.stdout
    assert "- gaitlib.library.layout -> gaitlib.meta.controller" in linted.stdout
