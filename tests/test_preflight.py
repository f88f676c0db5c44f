"""Every refusal comes before the work: options that contradict each other, paths that cannot be written, a missing
optional package and a library another process writes are refused in one line before the first simulated step,
creating nothing; a committed or marked library is written only with --replace, whatever its folder's name; the
refusals name what they refuse as it was given, and who holds a lock."""

from __future__ import annotations

import hashlib
import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import gaitlib_quick
from conftest import copy_library

from gaitlib.atomic import command_line
from gaitlib.library.layout import SHIPPED_MARKER, protection, shipped_library_dir
from gaitlib.library.target import library_writer

REPO = shipped_library_dir().parent


def _refused(result, line: str) -> None:
    assert (result.returncode, result.stdout, result.stderr) == (2, "", f"gaitlib: error: {line}\n")


def _tree(folder: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(folder)).encode() + path.read_bytes())
    return digest.hexdigest()


@pytest.fixture
def here(tiny_library, tmp_path, monkeypatch) -> Path:
    """An empty working folder of a user without $GAITLIB_LIBRARY, and no simulation allowed: a command that starts
    its work fails the test instead of being refused (the tests' library is trained first)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GAITLIB_LIBRARY", raising=False)

    def no_work(*args, **kwargs):
        raise AssertionError("the command simulated before refusing")

    for module, name in [("gaitlib.evaluation", "evaluate_policy"), ("gaitlib.training.trainer", "_train"),
                         ("gaitlib.meta.episode", "run_episode"), ("gaitlib.evaluation", "single_push_curve")]:
        monkeypatch.setattr(f"{module}.{name}", no_work)
    return tmp_path


CONFLICTS = [
    (["train", "stand", "--push-kind", "force", "--kick-max", "2"],
     "--kick-max has no effect with --push-kind force (its pushes are forces, not kicks): leave it out"),
    (["train", "stand", "--push-kind", "force", "--kick-draw", "disk", "--kick-interval", "1:2"],
     "--kick-draw, --kick-interval have no effect with --push-kind force (its pushes are forces, not kicks): leave "
     "them out"),
    (["eval", "stand", "--replace"], "--replace has no effect without --record (nothing is written): leave it out"),
    (["eval", "stand", "--plot", "p.png"],
     "--plot has no effect without --impulses (the push curve is what it plots): leave it out"),
    (["eval", "stand", "--impulses", "0:3:3", "--seconds", "5"],
     "--seconds has no effect with --impulses (each episode is the push curve's: one 0.1 s push, the trained delay): "
     "leave it out"),
    (["eval", "stand", "--impulses", "0:3:3", "--record"],
     "--record has no effect with --impulses (it stores the quality-bar evaluation, not a push curve): leave it out"),
    (["fit", "--evaluate", "--epochs", "3", "--replace"],
     "--replace, --epochs have no effect with --evaluate (it scores the library's net and fits nothing): leave them "
     "out"),
]


@pytest.mark.parametrize(("args", "line"), CONFLICTS, ids=[" ".join(a) for a, _ in CONFLICTS])
def test_options_that_contradict_each_other_are_refused_before_any_work(args, line, here) -> None:
    _refused(gaitlib_quick(*args), line)
    assert list(here.iterdir()) == []


PATHS = [
    (["train", "stand", "--preset", "tiny", "--library", "afile"], "--library afile is a file, not a library folder"),
    (["train", "stand", "--preset", "tiny", "--library", "lib", "--run-dir", "afile/run"],
     "--run-dir afile/run cannot be written: {here}/afile is a file, not a folder"),
    (["run", "--plot", "afile/run.png"],
     "--plot afile/run.png cannot be written: {here}/afile is a file, not a folder"),
    (["run", "--video", "afile/run.mp4"],
     "--video afile/run.mp4 cannot be written: {here}/afile is a file, not a folder"),
    (["eval", "stand", "--impulses", "0:3:3", "--plot", "afile/deeper/curve.png"],
     "--plot afile/deeper/curve.png cannot be written: {here}/afile is a file, not a folder"),
    (["eval", "stand", "--record", "--library", "afile"], "--library afile is a file, not a library folder"),
    (["collect", "--out", "afile/t.h5"], "--out afile/t.h5 cannot be written: {here}/afile is a file, not a folder"),
    (["states", "--out", "afile/s.npz"], "--out afile/s.npz cannot be written: {here}/afile is a file, not a folder"),
    (["benchmark", "--out", "afile"], "--out afile is a file, not a folder"),
    (["fit", "--library", "afile"], "--library afile is a file, not a library folder"),
    (["routes", "--out", "afile/b"], "--out afile/b cannot be written: {here}/afile is a file, not a folder"),
]


@pytest.mark.parametrize(("args", "line"), PATHS, ids=[" ".join(a) for a, _ in PATHS])
def test_a_path_that_cannot_be_written_is_refused_before_any_work_naming_it(args, line, here) -> None:
    (here / "afile").write_text("mine")
    _refused(gaitlib_quick(*args), line.format(here=here))
    assert sorted(p.name for p in here.iterdir()) == ["afile"] and (here / "afile").read_text() == "mine"


def test_a_video_without_imageio_is_refused_before_the_run(here, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "imageio", None)  # as if not installed
    refused = gaitlib_quick("run", "--video", "run.mp4", "--plot", "run.png")
    assert refused.returncode == 2 and refused.stderr.startswith("gaitlib: error: --video needs imageio")
    assert refused.stderr.rstrip("\n").endswith("not installed: pip install 'gaitlib[video]'")
    assert list(here.iterdir()) == []


@pytest.mark.parametrize("command", [
    ("eval", "stand", "--record", "--episodes", "64"),
    ("train", "stand", "--preset", "tiny", "--run-dir", "run"),
    ("fit", "--data", "t.h5"),
    ("routes", "--samples", "2", "--worlds", "2"),
])
def test_a_library_another_process_writes_is_refused_before_any_work_naming_both(command, tiny_library, here):
    library = copy_library(tiny_library, here / "library").root
    before = _tree(library)
    with library_writer(library, command="gaitlib fit"):
        refused = gaitlib_quick(*command, "--library", str(library))
    name = " ".join((*command[:1], *(["--record"] if "--record" in command else [])))
    holder = f"process {os.getpid()} ({command_line()})"
    _refused(refused, f"gaitlib {name} refused: library {library} is being written by {holder}")
    assert _tree(library) == before and sorted(p.name for p in here.iterdir()) == ["library"]


def test_the_holder_of_a_lock_is_named_by_its_command_line(tiny_library, tmp_path) -> None:
    """A second process holds the lock: the refusal names its id and the command it runs."""
    library = copy_library(tiny_library, tmp_path / "library").root
    script = ("import sys, time; from gaitlib.library.target import library_writer\n"
              "with library_writer(sys.argv[1], command='gaitlib fit'):\n"
              "    print('held', flush=True); time.sleep(60)\n")
    holder = subprocess.Popen([sys.executable, "-c", script, str(library), "--some-option"], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        refused = gaitlib_quick("routes", "--library", str(library), "--samples", "2")
    finally:
        holder.kill()
        holder.wait()
    line = shlex.join([os.path.basename(sys.executable), "-c", script, str(library), "--some-option"])
    _refused(refused, f"gaitlib routes refused: library {library} is being written by process {holder.pid} "
             f"({line.replace(chr(10), ' ')})")


# ------------------------------------------------------------------------------------------ protected libraries
@pytest.mark.parametrize("folder", ["library-paper", "library-switch-start"])
def test_a_committed_library_is_protected_whatever_its_name(folder, here) -> None:
    library = REPO / folder
    if protection(library) is None:
        pytest.skip("not a git checkout: the committed libraries are protected by git's index")
    before = _tree(library)
    for command in (("eval", "stand", "--record", "--episodes", "2", "--seconds", "1"),
                    ("fit", "--data", "nowhere.h5"), ("routes", "--samples", "2"),
                    ("train", "stand", "--preset", "tiny", "--run-dir", "run"),
                    ("train", "walk", "--preset", "tiny", "--run-dir", "run")):  # a new gait as well
        refused = gaitlib_quick(*command, "--library", str(library))
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
        assert f"of a protected library (committed to git), {library};" in refused.stderr
        assert "--replace" in refused.stderr
    assert _tree(library) == before and list(here.iterdir()) == []


def test_a_library_marked_or_committed_elsewhere_is_written_only_with_replace(tiny_library, here) -> None:
    marked = copy_library(tiny_library, here / "anything").root
    (marked / SHIPPED_MARKER).write_text("shipped data: write it only with --replace\n")
    committed = copy_library(tiny_library, here / "repo" / "mine").root
    for args in (["init", "-q"], ["add", "-A"], ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "x"]):
        subprocess.run(["git", *args], cwd=here / "repo", check=True, capture_output=True)
    assert protection(marked) == f"marked as shipped ({SHIPPED_MARKER})"
    assert protection(committed) == "committed to git" and protection(tiny_library.root) is None
    for library, why in ((marked, f"marked as shipped ({SHIPPED_MARKER})"), (committed, "committed to git")):
        before = _tree(library)
        refused = gaitlib_quick("eval", "stand", "--record", "--episodes", "2", "--library", str(library))
        _refused(refused, f"gaitlib eval --record would rewrite the entry stand of a protected library ({why}), "
                 f"{library}; it writes to your own library by default (runs/library, a copy of the shipped one, or "
                 "$GAITLIB_LIBRARY), or pass --replace to rewrite this one on purpose")
        assert _tree(library) == before
    assert not (here / "runs").exists()


def test_replace_writes_a_marked_library_and_a_copy_of_it_is_not_marked(tiny_library, tmp_path) -> None:
    marked = copy_library(tiny_library, tmp_path / "marked")
    (marked.root / SHIPPED_MARKER).write_text("shipped\n")
    done = gaitlib_quick("eval", "stand", "--record", "--replace", "--episodes", "2", "--seconds", "1",
                         "--backend", "mujoco", "--library", str(marked.root))
    assert done.returncode == 0, done.stderr
    assert marked.entry("stand").metadata["evaluation"]["episodes"] == 2
    from gaitlib.library.target import copy_library as copy_as_gaitlib_does

    mine = copy_as_gaitlib_does(marked.root, tmp_path / "mine")
    assert protection(mine) is None


# ------------------------------------------------------------------------------------------------------ messages
def test_a_value_is_named_as_given(here) -> None:
    _refused(gaitlib_quick("train", "stand", "--gamma", "1.0000001"),
             "--gamma must be a finite number in (0, 1], got 1.0000001")
    _refused(gaitlib_quick("collect", "--push-max", "2000.5"),
             "--push-max must be a finite number in [0, 2000] N, got 2000.5")


@pytest.mark.parametrize(("make", "state"), [(lambda p: p.mkdir(), "holds no gait entry"),
                                              (lambda p: None, "does not exist")])
def test_fitting_into_a_folder_that_is_not_a_library_names_the_folder_not_the_data(make, state, here) -> None:
    make(here / "notalib")
    _refused(gaitlib_quick("fit", "--library", "notalib", "--data", "missing.h5"),
             f"gaitlib fit: notalib is not a library ({state}); give --library a folder of trained gaits, or leave "
             "it out to write into your own library (runs/library)")


@pytest.mark.parametrize("extra", [[], ["--curve", "4,8"]], ids=["fit", "curve"])
def test_an_unknown_input_kind_is_refused_before_the_library_is_copied(extra, here) -> None:
    _refused(gaitlib_quick("fit", "--input", "latents", "--data", "missing.h5", *extra),
             "unknown input 'latents' (known: explicit, latent, phase)")
    assert list(here.iterdir()) == []
