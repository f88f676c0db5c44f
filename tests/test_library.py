"""The library object: its layout, the canonical gait order, identity checks, and fitting a library in one call."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import copy_library

from gaitlib.errors import TransitionDataError
from gaitlib.strategies.fitting import fit_library
from gaitlib.training import Library, LibraryError
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
    meta.write_text(json.dumps(json.loads(meta.read_text()) | {"format_version": 1}))
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
        fit_library(library, data((library.identities()["stand"], "f" * 64)), sources=["other.h5"], epochs=1)
    assert not library.net_path.exists() and not library.tmt_path.exists() and not library.accuracy_path.exists()
    own = data(tuple(library.identities().values()))
    report = fit_library(library, own, sources=[tmp_path / "own.h5"], inputs=("phase", "latent"), epochs=1)
    written = json.loads(library.accuracy_path.read_text())
    assert written == report.as_dict() and written["input_written"] == "phase"
    assert written["written"] == ["transition_net/net.pt", "tmt/tmt.json", "transition_net/accuracy.json"]
    assert set(written["balanced_validation_accuracy"]) == {"phase", "latent"}
    assert written["paper_table_3"]["latent"]["trot-stand"] == pytest.approx(0.7549)  # fractions, like ours
