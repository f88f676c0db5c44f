"""The build step that puts the shipped library into the package: ``library/`` of the repository is copied into
the wheel as ``gaitlib/library/shipped/``, where an installed gaitlib finds it
(:func:`gaitlib.library.layout.shipped_library_dir`). An editable install copies nothing: it runs from the checkout
and reads the checkout's ``library/``. Everything else about the build is in ``pyproject.toml``."""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.errors import FileError

LIBRARY = Path(__file__).resolve().parent / "library"
PACKAGED = Path("gaitlib") / "library" / "shipped"  # gaitlib.library.layout.PACKAGED_LIBRARY


class BuildPyWithLibrary(build_py):
    """``build_py``, then the shipped library copied into the build (nothing written beside the sources)."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        if not LIBRARY.is_dir():
            raise FileError(f"the shipped library {LIBRARY} is missing: a wheel of gaitlib must carry it")
        target = Path(self.build_lib) / PACKAGED
        shutil.rmtree(target, ignore_errors=True)  # a build folder left from an earlier build holds no stale file
        shutil.copytree(LIBRARY, target, ignore=shutil.ignore_patterns(".*", "__pycache__"))


setup(cmdclass={"build_py": BuildPyWithLibrary})
