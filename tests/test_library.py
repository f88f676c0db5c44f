"""The library object: its layout, the canonical gait order, identity checks, and fitting a library in one call."""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import copy_library, rsl_rl_models, trained_models, write_foreign_json

from gaitlib.atomic import write_json
from gaitlib.envs.observations import ObservationConfig
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.gaits import get_gait
from gaitlib.library import Library, LibraryError, publish
from gaitlib.strategies.fitting import fit_library
from gaitlib.transitions import read
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader


def test_hidden_or_temporary_folders_are_never_gaits(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    shutil.copytree(library.root / "stand", library.root / ".stand.old")  # left by a replaced entry
    shutil.copytree(library.root / "trot", library.root / ".trot.k2x9")  # a staging folder of a killed write
    assert library.gaits() == ("stand", "trot")


def test_gaits_are_put_in_one_canonical_order_and_unknown_ones_refused(tiny_library) -> None:
    assert tiny_library.order(["trot", "stand", "trot"]) == ("stand", "trot")
    assert tiny_library.order(None) == tiny_library.gaits() == ("stand", "trot")
    with pytest.raises(LibraryError, match=r"no library entry for gait 'gallop' .*\(entries: stand, trot\)"):
        tiny_library.order(["trot", "gallop"])


def test_files_made_for_other_policies_are_refused(tiny_library) -> None:
    ids = tiny_library.identities()
    assert list(ids) == ["stand", "trot"] and all(len(i) == 64 for i in ids.values())
    tiny_library.check_identities(ids, what="x")  # the library's own
    with pytest.raises(TransitionDataError, match="x needs gait 'pace', which the library does not hold"):
        tiny_library.check_identities({"pace": "p" * 64}, what="x")
    with pytest.raises(TransitionDataError, match="x was made for another 'trot' policy"):
        tiny_library.check_identities(ids | {"trot": "t" * 64}, what="x")


def test_an_entry_of_an_older_format_gets_one_line(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    meta = library.root / "stand" / "metadata.json"
    write_json(meta, json.loads(meta.read_text()) | {"format_version": 1}, checksum=True)
    with pytest.raises(LibraryError, match="'stand' has format version 1, this gaitlib reads version 2"):
        library.entry("stand")


def test_fitting_on_data_of_other_policies_is_refused_before_anything_is_written(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    n = 40
    rng = np.random.default_rng(0)
    source = np.repeat([0, 1], n // 2)
    batch = TransitionBatch(
        source=source, dest=1 - source, latent=rng.normal(size=(n, 16)), phase_source=rng.random(n),
        phase_dest=rng.random(n), explicit=rng.normal(size=(n, 66)), value_source=np.ones(n), value_dest=np.ones(n),
        push_force=np.zeros(n), success=np.tile([0, 1], n // 2), switch_time=np.ones(n), world=np.zeros(n),
        chunk=np.zeros(n),
    )

    def data(identities: tuple[str, str]) -> TransitionData:
        header = TransitionHeader(gaits=("stand", "trot"), identities=identities, latent_dim=16, settings={})
        return TransitionData(TransitionFileInfo(header, n, [], None), batch)

    with pytest.raises(TransitionDataError, match="another 'trot' policy"):  # trot collected with another policy
        fit_library(library, data((library.identities()["stand"], "f" * 64)), sources=["other.h5"], epochs=1,
                    min_per_label=0)
    assert not library.switching_dir.exists()
    own = data(tuple(library.identities().values()))
    report = fit_library(library, own, sources=[tmp_path / "own.h5"], inputs=("phase", "latent"), epochs=1,
                         min_per_label=0)
    written = json.loads(library.accuracy_path.read_text())
    assert written == report.as_dict() | {"checksum": written["checksum"]} and written["input_written"] == "phase"
    assert written["written"] == [
        "switching/net.pt", "switching/tmt.json", "switching/accuracy.json", "switching/calibration.json",
        "switching/checksums.json",
    ]
    assert set(written["balanced_validation_accuracy"]) == {"phase", "latent"}
    assert written["paper_table_3"]["latent"]["trot-stand"] == pytest.approx(0.7549)  # fractions, like ours


# A child process rewrites a library folder and is killed (SIGKILL, as by the OOM killer or `kill -9`) at a chosen
# point; the library must then hold the old version or the new one, whole.
def _killed_writer(root: Path, where: str, data: Path | None) -> None:
    """A writer killed (SIGKILL, nothing cleaned up) at ``where``: replacing the stand's entry with new weights, or
    in the middle of a fit. Runs in a forked child (:func:`_kill_a_writer`), so its patches never reach this
    process."""
    import torch

    torch.set_num_threads(1)  # a forked child keeps none of the parent's intra-op threads

    def die(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGKILL)

    library = Library(root)
    if where == "before-swap":
        publish._swap_in = die
    elif where == "after-swap":
        publish.shutil.rmtree = die  # removes the old version, the step after the exchange
    elif where == "between-renames":  # a system that cannot exchange two folders: the two-rename fallback
        publish.exchange = lambda a, b: False
        rename, calls = os.rename, []
        os.rename = lambda a, b: calls.append(a) or (die() if len(calls) == 2 else rename(a, b))
    elif where == "mid-fit":
        import gaitlib.strategies.fitting as fitting

        fitting.save_table = die  # the net is written, the TMT and accuracy not yet
        fit_library(library, read(data), sources=[str(data)], epochs=1, seed=1, min_per_label=0)
        return
    entry = library.entry("stand")
    actor, critic = trained_models(library, "stand")
    with torch.no_grad():
        next(actor.parameters()).add_(1.0)  # new weights: a new identity
    library.save_entry(
        description=entry.description, actor=actor, critic=critic,
        networks=entry.metadata["networks"], action=entry.action, observation=entry.observation, training={},
        evaluation={},
    )


def _kill_a_writer(root: Path, where: str, data: Path | None = None) -> int:
    """:func:`_killed_writer` in a child forked from this process (its imports done: no interpreter to start);
    the child's exit code, ``-SIGKILL`` where the kill came."""
    child = multiprocessing.get_context("fork").Process(target=_killed_writer, args=(root, where, data))
    child.start()
    child.join(timeout=120)
    return child.exitcode


@pytest.mark.parametrize(
    ("where", "survivor"), [("before-swap", "old"), ("after-swap", "new"), ("between-renames", "old")]
)
def test_a_writer_killed_while_replacing_an_entry_leaves_the_old_or_the_new_one(
    tiny_library, tmp_path, where, survivor
) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    old = library.identities()
    assert _kill_a_writer(library.root, where) == -signal.SIGKILL
    after = Library(library.root)
    assert after.gaits() == ("stand", "trot") and after.identities()["trot"] == old["trot"]
    assert (after.identities()["stand"] == old["stand"]) == (survivor == "old")
    entry = after.entry("stand")  # whole: its checksum and files agree
    actor, critic = trained_models(after, "stand")
    after.save_entry(  # the next write cleans what the killed one left
        description=entry.description, actor=actor, critic=critic,
        networks=entry.metadata["networks"], action=entry.action, observation=entry.observation, training={},
        evaluation={},
    )
    assert sorted(p.name for p in library.root.iterdir() if p.is_dir()) == ["stand", "trot"]


def _new_stand(library: Library) -> None:
    """Write the entry ``stand`` of ``library`` again, with new weights (a new identity)."""
    entry = library.entry("stand")
    actor, critic = trained_models(library, "stand")
    with torch.no_grad():
        next(actor.parameters()).add_(1.0)
    library.save_entry(description=entry.description, actor=actor, critic=critic, networks=entry.metadata["networks"],
                       action=entry.action, observation=entry.observation, training={}, evaluation={})


@pytest.mark.parametrize("exchanges", [True, False], ids=["exchange", "two renames"])
def test_an_entry_linked_to_another_librarys_is_replaced_by_its_own_and_the_other_is_untouched(
    tiny_library, tmp_path, monkeypatch, exchanges
) -> None:
    """A grown library holds its first gaits as links to the library they came from; writing one replaces the link
    with a folder of its own, leaves the linked folder byte for byte, and leaves nothing behind, also where a killed
    writer left a link among its staging folders."""
    first = copy_library(tiny_library, tmp_path / "first")
    before = {p: p.read_bytes() for p in first.root.rglob("*") if p.is_file()}
    grown = tmp_path / "grown"
    grown.mkdir()
    for gait in ("stand", "trot"):
        (grown / gait).symlink_to(Path("..") / "first" / gait)
    (grown / ".stand.killed").symlink_to(Path("..") / "first" / "stand")  # what a killed writer left
    if not exchanges:
        monkeypatch.setattr(publish, "exchange", lambda a, b: False)
    _new_stand(Library(grown))
    after = Library(grown)
    assert not (grown / "stand").is_symlink() and (grown / "trot").is_symlink()
    assert after.identities()["stand"] != first.identities()["stand"]
    assert after.identities()["trot"] == first.identities()["trot"]
    assert {p: p.read_bytes() for p in first.root.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in grown.iterdir() if p.name.startswith(".")) == []


def test_a_fit_killed_midway_leaves_the_previous_switching_models_whole(switching_library, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    before = {p.name: p.read_bytes() for p in library.switching_dir.iterdir()}
    data = switching_library.parent / "samples.h5"
    assert _kill_a_writer(library.root, "mid-fit", data) == -signal.SIGKILL
    assert {p.name: p.read_bytes() for p in library.switching_dir.iterdir()} == before


def test_a_second_writer_of_an_entry_is_refused_in_one_line(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    entry = library.entry("stand")
    actor, critic = trained_models(library, "stand")
    held = rf"library/stand is being written by process {os.getpid()} \(.+\)$"
    with publish._writer_lock(library.root / "stand"), pytest.raises(GaitlibError, match=held):
        library.save_entry(
            description=entry.description, actor=actor, critic=critic,
            networks=entry.metadata["networks"], action=entry.action, observation=entry.observation,
            training={}, evaluation={},
        )
    assert library.entry("stand").identity == tiny_library.entry("stand").identity


def test_a_library_without_switching_models_names_the_commands_that_make_them(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    first_fit = r"has no transition-net and TMT yet; make them: gaitlib collect --library .* && gaitlib fit "
    with pytest.raises(TransitionDataError, match=first_fit):
        library.check_switching()


@pytest.mark.parametrize(
    "change",
    [
        lambda meta: meta.pop("action"),
        lambda meta: meta["action"].update(clip="4.0"),
        lambda meta: meta["action"].update(scale=float("nan")),
        lambda meta: meta["action"].pop("type"),
    ],
    ids=["no action", "a string clip", "a nan scale", "no type"],
)
def test_an_entry_with_damaged_action_settings_gets_one_line(tiny_library, tmp_path, change) -> None:
    library = copy_library(tiny_library, tmp_path / "library")
    path = library.root / "trot" / "metadata.json"
    meta = json.loads(path.read_text())
    change(meta)
    write_foreign_json(path, meta)
    with pytest.raises(LibraryError, match=r"^library entry 'trot' has damaged metadata: 'action' needs .*, got "):
        library.entry("trot")


def test_a_missing_gait_folder_is_named_as_missing(tmp_path) -> None:
    from gaitlib.meta import load_switching
    from gaitlib.strategies import get_strategy

    root = tmp_path / "library"
    shutil.copytree(Library().root, root, ignore=shutil.ignore_patterns("stand"))  # the shipped library, no stand
    setup = load_switching(root)
    for strategy in ("tmt", "net"):
        with pytest.raises(TransitionDataError, match=r"fitted with stand, which the library no longer holds; fix: "):
            get_strategy(strategy, setup.resources)


def test_entries_that_read_other_observations_are_not_mixed(tiny_library, tmp_path) -> None:
    """An entry of gaitlib 0.1's layout (158 values, no heading error, trained without an action delay) loads, and
    runs as it was trained; beside the current layout's entries it is refused in one line."""
    library = copy_library(tiny_library, tmp_path / "library")
    entry = library.entry("stand")
    old = ObservationConfig(heading=False)
    actor, critic = rsl_rl_models(actor_hidden=(32, 16), critic_hidden=(32, 16), observation=old)
    library.save_entry(
        description=get_gait("pace"), actor=actor, critic=critic, networks=entry.metadata["networks"],
        action=entry.action, observation=old, training={}, evaluation={},
    )
    pace = Library(library.root).entry("pace")
    assert pace.observation == old and pace.action_delay_steps == (0, 0)
    assert Library(library.root).shared_policy_settings(["pace"]).observation == old
    assert library.shared_policy_settings(["stand", "trot"]).action_delay_steps == (0, 1)
    with pytest.raises(LibraryError, match=r"have different observations .*; retrain them like "):
        Library(library.root).shared_policy_settings()
