"""``benchmarks/clean_clone_suite.py`` times what a commit's ``.ci/run`` does in a fresh clone, on a small repository
made here whose ``.ci/run`` prints a pytest summary."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from benchmarks.clean_clone_suite import clean_clone_run, reference_seconds

RUN = """#!/usr/bin/env bash
set -euo pipefail
[ "${CI:-}" = true ] || exit 3
sleep 0.3
echo "========== 4 passed, 1 skipped in 0.10s =========="
"""


def _repo(folder: Path) -> Path:
    (folder / ".ci").mkdir(parents=True)
    (folder / ".ci" / "run").write_text(RUN)
    for args in (["init", "--quiet"], ["add", "-A"],
                 ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "--quiet", "-m", "a suite"]):
        subprocess.run(["git", "-C", str(folder), *args], check=True)
    return folder


def test_a_clean_clone_of_the_commit_runs_its_ci_and_is_timed(tmp_path: Path) -> None:
    repo = _repo(tmp_path / "repo")
    (repo / ".ci" / "run").write_text("exit 5\n")  # not committed: a clean clone does not see it
    run = clean_clone_run(repo, "HEAD")
    head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    assert (run["commit"], run["returncode"], run["summary"], run["tests_s"]) == (head, 0, "4 passed, 1 skipped", 0.1)
    assert run["total_s"] >= 0.3 and run["install_s"] == round(run["total_s"] - 0.1, 1)
    assert run["warp_cache"] == "warm"


def test_an_empty_warp_cache_is_a_fresh_folder_of_the_run(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.delenv("WARP_CACHE_PATH", raising=False)  # even when this suite runs in an empty cache
    repo = _repo(tmp_path / "repo")
    empty = '[ -d "$WARP_CACHE_PATH" ] && [ -z "$(ls -A "$WARP_CACHE_PATH")" ]'  # the run fails unless it is given one
    (repo / ".ci" / "run").write_text(RUN.replace("sleep 0.3", empty))
    subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", "commit", "--quiet", "-am",
                    "checks its cache"], check=True)
    assert clean_clone_run(repo, "HEAD")["returncode"] != 0  # the machine's cache: no WARP_CACHE_PATH
    run = clean_clone_run(repo, "HEAD", empty_warp_cache=True)
    assert (run["returncode"], run["warp_cache"]) == (0, "empty")


def test_an_unknown_commit_is_refused_in_one_line(tmp_path: Path) -> None:
    repo = _repo(tmp_path / "repo")
    with pytest.raises(SystemExit, match=r"^clean_clone_suite: .*repo has no commit 'no-such-commit'$"):
        clean_clone_run(repo, "no-such-commit")


def test_the_reference_computation_is_timed_in_a_fresh_interpreter() -> None:
    assert 0 < reference_seconds(runs=1) < 60
