"""A full disk ends every writing command in one line, never a traceback or a crash, and keeps what was committed
before: each command runs on a real small file system (a tmpfs mounted in a user and mount namespace, ``unshare
-rm``, filled but for a few KiB), so the writes fail with ENOSPC from the kernel, wherever they are made (HDF5,
torch, Python)."""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import gaitlib_quick

from gaitlib.transitions import validate

CLI = f"{shlex.quote(sys.executable)} -c 'from gaitlib.cli import main; main()'"


def _namespaces() -> bool:
    if shutil.which("unshare") is None:
        return False
    try:
        return subprocess.run(["unshare", "-rm", "true"], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


pytestmark = pytest.mark.skipif(not _namespaces(), reason="no user and mount namespaces (unshare -rm): no small "
                                "file system to fill")


def on_a_small_disk(tmp_path: Path, script: str) -> subprocess.CompletedProcess[str]:
    """Run the shell ``script`` where ``$DISK`` is a fresh 64 MiB tmpfs (gone when it ends) and ``fill_but K``
    fills it but for K KiB; ``$CLI`` runs gaitlib. Its stdout, stderr and exit status come back."""
    disk = tmp_path / "disk"
    disk.mkdir()
    body = (f"set -u; DISK={shlex.quote(str(disk))}; CLI={shlex.quote(CLI)}; "
            "mount -t tmpfs -o size=64m tmpfs \"$DISK\" || exit 99; "
            "fill_but() { dd if=/dev/zero of=\"$DISK/.fill\" bs=64k 2>/dev/null; "
            "truncate -s -\"$1\"K \"$DISK/.fill\"; }\n" + script)
    return subprocess.run(["unshare", "-rm", "sh", "-c", body], capture_output=True, text=True, timeout=600)


def _one_line(stderr: str, start: str) -> None:
    """The run ended with one error line starting ``start``, and printed no traceback."""
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr
    assert stderr.splitlines()[-1].startswith(start), stderr


def test_collect_on_a_full_disk_keeps_its_committed_samples_in_one_line(tiny_library, tmp_path) -> None:
    options = ("--library", str(tiny_library.root), "--worlds", "4", "--chunk", "4", "--horizon", "0.5", "--backend",
               "mujoco", "--seed", "0")
    first = tmp_path / "first"
    first.mkdir()
    assert gaitlib_quick("collect", *options, "--out", str(first / "t.h5"), "--samples", "4").returncode == 0
    done = on_a_small_disk(tmp_path, f"""
cp -r {first}/t.h5 {first}/t.h5.parts "$DISK"/
fill_but 4
eval "$CLI" collect {shlex.join(options)} --out "$DISK/t.h5" --samples 400
echo "status $?"
mkdir {tmp_path}/kept && cp -r "$DISK/t.h5" "$DISK/t.h5.parts" {tmp_path}/kept/
""")
    assert "status 2" in done.stdout, done.stderr  # one line: no segfault (139), no traceback (1)
    _one_line(done.stderr, f"gaitlib: error: could not write {tmp_path}/disk/t.h5")
    assert done.stderr.splitlines()[-1].endswith(": no space left on device; the 4 samples committed before are "
                                                  "kept: free space and rerun to resume")
    assert validate(tmp_path / "kept" / "t.h5").count == 4  # every committed sample reads back (each part checked)


def test_fit_on_a_full_disk_leaves_the_models_as_they_were_in_one_line(switching_library, tmp_path) -> None:
    done = on_a_small_disk(tmp_path, f"""
cp -r {switching_library} "$DISK/library"
before=$(cat "$DISK"/library/switching/* | sha256sum)
fill_but 24
eval "$CLI" fit --library "$DISK/library" --data {switching_library.parent / 'samples.h5'} --epochs 1 \\
    --min-per-label 0
echo "status $?"
[ "$before" = "$(cat "$DISK"/library/switching/* | sha256sum)" ] && echo unchanged
ls -a "$DISK/library"
""")
    assert "status 1" in done.stdout, done.stderr
    _one_line(done.stderr, f"gaitlib: error: no space left on the device writing {tmp_path}/disk/library/switching/")
    assert "unchanged" in done.stdout
    assert not [name for name in done.stdout.split() if name.startswith(".switching.")]  # no staging folder left


def test_eval_record_on_a_full_disk_leaves_the_entry_as_it_was_in_one_line(tiny_library, tmp_path) -> None:
    done = on_a_small_disk(tmp_path, f"""
cp -r {tiny_library.root} "$DISK/library"
before=$(cat "$DISK"/library/stand/* | sha256sum)
fill_but 4
eval "$CLI" eval stand --record --episodes 2 --seconds 0.5 --backend mujoco --library "$DISK/library"
echo "status $?"
[ "$before" = "$(cat "$DISK"/library/stand/* | sha256sum)" ] && echo unchanged
""")
    assert "status 1" in done.stdout, done.stderr
    _one_line(done.stderr, "gaitlib: error: no space left on the device writing ")
    assert "unchanged" in done.stdout


def test_training_that_cannot_publish_on_a_full_disk_says_so_in_one_line_and_keeps_its_checkpoint(tmp_path) -> None:
    run_dir = tmp_path / "run"
    done = on_a_small_disk(tmp_path, f"""
mkdir "$DISK/library"
fill_but 8
eval "$CLI" train stand --preset tiny --iterations 1 --eval-episodes 2 --eval-seconds 0.5 --backend mujoco \\
    --library "$DISK/library" --run-dir {run_dir}
echo "status $?"
""")
    assert "status 1" in done.stdout, done.stderr
    _one_line(done.stderr, f"gaitlib: error: no space left on the device writing {tmp_path}/disk/library/")
    assert done.stderr.splitlines()[-1].endswith("(train: with --resume)")
    assert (run_dir / "checkpoints" / "latest.pt").is_file()
