"""gaitlib as it installs: the package's layers as an import-linter contract that an upward import breaks, the
wheel carrying the shipped library and running the README's main job from a venv outside the source tree, and
``gaitlib --version``."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from importlib.metadata import version
from pathlib import Path

from cli_runner import gaitlib_quick
from conftest import REPO

import gaitlib
from gaitlib.library.layout import PACKAGED_LIBRARY

LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
"""import-linter's command, installed beside this interpreter (the ``test`` extra)."""


def lint_imports(root: Path) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` in ``root``: its ``gaitlib`` package against the contracts of its ``pyproject.toml``."""
    env = os.environ | {"PYTHONPATH": str(root)}
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache"],
        cwd=root, env=env, capture_output=True, text=True, timeout=120,
    )


def succeeded(*command: str) -> str:
    """Run ``command`` (nothing is downloaded: every pip call is ``--no-index``); its stdout, once it exited 0."""
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


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


def test_version_is_one_line_from_the_package_metadata() -> None:
    shown = gaitlib_quick("--version")
    assert shown.returncode == 0 and shown.stderr == ""
    assert shown.stdout == f"gaitlib {version('gaitlib')}\n" and version("gaitlib") == gaitlib.__version__


def test_the_wheel_carries_the_shipped_library_and_runs_the_main_job_outside_the_source_tree(
    fresh_copy, tmp_path
) -> None:
    """Build the wheel of a fresh clone, install it alone into a new venv that reaches the dependencies already
    installed here, and run the README's main job from an empty folder: it reads the library inside the package,
    which the protection of the shipped library knows as the shipped one."""
    succeeded(sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
              "-w", str(tmp_path / "dist"), str(fresh_copy))
    (wheel,) = (tmp_path / "dist").glob("gaitlib-*.whl")
    packaged = f"gaitlib/library/{PACKAGED_LIBRARY}/"
    shipped = {p.relative_to(REPO / "library").as_posix(): p.read_bytes()
               for p in (REPO / "library").rglob("*") if p.is_file() and not p.name.startswith(".")}
    with zipfile.ZipFile(wheel) as archive:
        carried = {n.removeprefix(packaged): archive.read(n) for n in archive.namelist() if n.startswith(packaged)}
    assert carried.keys() == shipped.keys() and carried == shipped  # every file of library/, byte for byte

    venv = tmp_path / "venv"
    succeeded(sys.executable, "-m", "venv", "--without-pip", str(venv))
    python = venv / "bin" / "python"
    site = Path(succeeded(str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip())
    here = dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    (site / "dependencies.pth").write_text("".join(f"{path}\n" for path in here))  # torch, mujoco, ... of this venv
    succeeded(sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index",
              str(wheel))

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GAITLIB_LIBRARY")}
    installed_library = site / "gaitlib" / "library" / PACKAGED_LIBRARY
    commands = {
        "main job": ["run", "--from", "trot", "--to", "stand"],
        "refusal": ["fit", "--data", "nowhere.h5", "--library", str(installed_library)],
    }
    started = {what: subprocess.Popen([str(venv / "bin" / "gaitlib"), *args], cwd=elsewhere, env=env, text=True,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE)
               for what, args in commands.items()}
    done = {what: (process.communicate(timeout=600), process.returncode) for what, process in started.items()}

    (out, err), code = done["main job"]
    assert code == 0, err
    assert "trot -> stand with net-lookahead: 1 of 1 switch(es) made; the robot stayed up" in out
    assert (elsewhere / "run.png").is_file()
    (out, err), code = done["refusal"]  # the installed copy is the shipped library: written only with --replace
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"would rewrite the switching models of the shipped library, {installed_library};" in err
    assert sorted(p.name for p in elsewhere.iterdir()) == ["run.png"]
