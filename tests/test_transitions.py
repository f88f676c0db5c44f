"""Transition samples: the HDF5 schema (round trip, merged parts, leftovers, clear errors) and real collections
with tiny policies."""

from __future__ import annotations

import dataclasses
import re
import shutil

import h5py
import numpy as np
import pytest
import torch

from gaitlib.collection import CollectConfig, collect
from gaitlib.errors import TransitionDataError
from gaitlib.meta import TrialProtocol
from gaitlib.transitions import explicit_state, read, read_all, schema, validate
from gaitlib.transitions.schema import COLUMNS, TransitionBatch, TransitionHeader
from gaitlib.transitions.writer import FAN_IN, open_writer

GAITS = ["stand", "trot"]
DT = 1 / 30  # control period, s
# Short cycles keep the collections to a few seconds; with strong pushes (up to 400 N) the untrained policies fall
# often enough for both labels.
QUICK = CollectConfig(
    samples=24, num_worlds=4, push_max=400.0, backend="mujoco", chunk=8,
    protocol=TrialProtocol.collection(horizon_s=1.5, warmup_s=0.3, source_extra_s=0.5),
)


@pytest.fixture(scope="module")
def library(tiny_library):
    """The tests' tiny library (read only here)."""
    return tiny_library


@pytest.fixture(scope="module")
def interrupted(library, tmp_path_factory):
    """A collection stopped by Ctrl-C after its first chunk, the file's columns then, and the resumed result."""
    path = tmp_path_factory.mktemp("collect") / "samples.h5"

    def stop(progress):
        if progress.under_way == 0:  # a commit's report, not one from inside the chunk
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        collect(path, library=library, gaits=GAITS, config=QUICK, progress=stop)
    before = read(path).samples
    seen = []
    result = collect(path, library=library, gaits=GAITS, config=QUICK, progress=seen.append)
    return path, before, result, seen


def synthetic(n: int, *, latent_dim: int = 4, start: int = 0, seed: int = 0) -> TransitionBatch:
    rng = np.random.default_rng(seed)
    source = rng.integers(0, 2, n)
    return TransitionBatch(
        source=source,
        dest=1 - source,
        latent=rng.normal(size=(n, latent_dim)),
        phase_source=rng.random(n),
        phase_dest=rng.random(n),
        explicit=rng.normal(size=(n, 66)),
        value_source=rng.normal(size=n),
        value_dest=rng.normal(size=n),
        push_force=rng.random(n) * 100,
        success=rng.integers(0, 2, n),
        switch_time=rng.random(n) * 3,
        world=np.arange(start, start + n) % 4,
        chunk=np.full(n, start),
    )


HEADER = TransitionHeader(gaits=("stand", "trot"), identities=("a" * 64, "b" * 64), latent_dim=4, settings={"h": 2.0})


def make_file(path, *batches: TransitionBatch, header: TransitionHeader = HEADER):
    with open_writer(path, header=header) as writer:
        for batch in batches:
            writer.append(batch)
    return path


def one_line_error(path) -> str:
    """The one-line message with which ``validate`` refuses ``path``; every such message names the file."""
    with pytest.raises(TransitionDataError, match=re.escape(str(path))) as caught:
        validate(path)
    message = str(caught.value)
    assert "\n" not in message
    return message


def assert_same(samples: TransitionBatch, expected: TransitionBatch) -> None:
    """Every column equal, bit for bit, with the schema's dtypes."""
    for name, values in expected.columns().items():
        np.testing.assert_array_equal(getattr(samples, name), values)
        assert getattr(samples, name).dtype == np.dtype(COLUMNS[name].dtype)


# ------------------------------------------------------------------------------------------------------ schema
def test_batch_fields_are_the_schema_columns() -> None:
    assert [f.name for f in dataclasses.fields(TransitionBatch)] == list(COLUMNS)


def test_appended_batches_read_back_exactly(tmp_path) -> None:
    first, second = synthetic(5), synthetic(7, start=5, seed=1)
    path = make_file(tmp_path / "t.h5", first, second)
    data = read(path)
    assert_same(data.samples, TransitionBatch.concatenate([first, second]))
    info = validate(path)
    assert info.count == 12 and info.note is None and info.header == HEADER
    parts = sorted(p.name for p in schema.parts_folder(path).iterdir())
    assert parts == ["part-000000000000-000000000005.h5", "part-000000000005-000000000012.h5"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.h5", "t.h5.parts"]  # the lock went with the writer
    with h5py.File(path) as f:
        assert f.attrs["schema"] == schema.SCHEMA_NAME and f.attrs["schema_version"] == schema.SCHEMA_VERSION == 4
        assert f.attrs["count"] == 12 and [int(r) for r in f["parts"]["rows"]] == [5, 7]
    with h5py.File(schema.parts_folder(path) / parts[1]) as f:
        ds = f["latent"]
        assert ds.compression == "gzip" and ds.fletcher32 and ds.shape == (7, 4)
        assert "description" in ds.attrs and f["push_force"].attrs["units"] == "N"


def test_small_parts_are_merged_and_read_the_same(tmp_path) -> None:
    batches = [synthetic(2, start=2 * i, seed=i) for i in range(2 * FAN_IN + 1)]
    path = make_file(tmp_path / "t.h5", *batches)
    parts = sorted(p.name for p in schema.parts_folder(path).iterdir())
    assert parts == ["part-000000000000-000000000032.h5", "part-000000000032-000000000064.h5",
                     "part-000000000064-000000000066.h5"]
    assert_same(read(path).samples, TransitionBatch.concatenate(batches))


def test_leftovers_of_a_killed_writer_are_ignored_then_removed(tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(6))
    folder = schema.parts_folder(path)
    shutil.copy(folder / "part-000000000000-000000000006.h5", folder / "part-000000000006-000000000012.h5")
    (folder / ".part-000000000006-000000000008.h5.x1.tmp.h5").write_bytes(b"half")
    (tmp_path / ".t.h5.x2.tmp.h5").write_bytes(b"half an index")
    assert "1 uncommitted part files are ignored" in validate(path).note
    assert len(read(path).samples) == 6
    with open_writer(path, header=HEADER) as writer:
        assert writer.count == 6 and "removed 3 uncommitted files" in writer.note
        writer.append(synthetic(2, start=6))
    info = validate(path)
    assert info.count == 8 and info.note is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.h5", "t.h5.parts"]


def test_appending_with_other_settings_or_identities_is_refused(tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(2))
    with pytest.raises(TransitionDataError, match=r"other settings \(h: 2.0 in the file, 1.0 now\)"):
        open_writer(path, header=dataclasses.replace(HEADER, settings={"h": 1.0}))
    with pytest.raises(TransitionDataError, match="other library policies for trot"):
        open_writer(path, header=dataclasses.replace(HEADER, identities=("a" * 64, "c" * 64)))
    make_file(path, synthetic(1, start=2))  # the refusals released the lock


def test_truncated_index_or_part_is_one_clear_error(tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(300))
    part = schema.parts_folder(path) / "part-000000000000-000000000300.h5"
    data = part.read_bytes()
    part.write_bytes(data[: len(data) // 2])
    assert "part part-000000000000-000000000300.h5 does not match its checksum" in one_line_error(path)
    part.unlink()
    assert "part part-000000000000-000000000300.h5 listed in its index is missing" in one_line_error(path)
    index = path.read_bytes()
    path.write_bytes(index[: len(index) // 2])
    assert "corrupt or truncated" in one_line_error(path)


def test_foreign_and_non_hdf5_files_are_clear_errors(tmp_path) -> None:
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    assert "not gaitlib transition data (no 'schema' attribute)" in one_line_error(foreign)
    text = tmp_path / "notes.h5"
    text.write_text("hello")
    assert "not an HDF5 file" in one_line_error(text)
    assert "no transition file" in one_line_error(tmp_path / "missing.h5")


def test_other_schema_versions_are_clear_errors(tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(5))
    for version in (1, 2, 3, 5):
        with h5py.File(path, "r+") as f:
            f.attrs["schema_version"] = version
        assert f"schema version {version}; this gaitlib reads version 4 only" in one_line_error(path)
        before = path.read_bytes()
        with pytest.raises(TransitionDataError, match=rf"schema version {version}; .*collect into a new file"):
            open_writer(path, header=HEADER)
        assert path.read_bytes() == before


@pytest.mark.parametrize(
    ("name", "value"),
    [("settings", '{"h": 2.5}'), ("gaits", ["trot", "stand"]), ("library_identities", ["x" * 64, "y" * 64]),
     ("latent_dim", 5), ("sessions", '[{"seed": 9}]'), ("count", 4)],
)
def test_an_index_changed_after_it_was_written_is_refused(tmp_path, name, value) -> None:
    """A flipped bit in the stored settings (a horizon read as another), swapped gaits or identities: each would
    relabel or mis-judge samples silently; the index checksum refuses them."""
    path = make_file(tmp_path / "t.h5", synthetic(5))
    with h5py.File(path, "r+") as f:
        f.attrs[name] = value
    assert "its index does not match its checksum" in one_line_error(path)


def test_explicit_state_drops_the_actions_of_each_frame() -> None:
    obs = torch.arange(2 * 158, dtype=torch.float32).reshape(2, 158)
    state = explicit_state(obs)
    assert state.shape == (2, 66)
    np.testing.assert_array_equal(state[0, 22:44], obs[0, 34:56])


# ------------------------------------------------------------------------------------------------- collection
def test_collection_writes_a_valid_file_with_both_labels(library, interrupted) -> None:
    path, _, result, _ = interrupted
    info = validate(path)
    assert info.count == result.samples == 24
    assert info.header.gaits == tuple(GAITS)
    assert info.header.identities == tuple(library.identities(GAITS).values())
    assert info.header.settings["horizon_s"] == QUICK.protocol.horizon_s and info.header.settings["backend"] == "mujoco"
    assert info.header.settings["push_max_n"] == QUICK.push_max
    s = read(path).samples
    assert set(s.success.tolist()) == {0, 1}
    assert np.all(s.source != s.dest) and set(s.source.tolist()) == {0, 1}
    counts = np.bincount(s.source, minlength=2)
    assert abs(counts[0] - counts[1]) <= QUICK.num_worlds  # pairs are filled evenly
    assert s.latent.shape == (24, 16) and s.explicit.shape == (24, 66)
    assert np.all((s.phase_source >= 0) & (s.phase_source < 1) & (s.phase_dest >= 0) & (s.phase_dest < 1))
    assert np.all(s.switch_time >= QUICK.protocol.warmup_s - 1e-4)
    assert np.all((s.push_force >= 0) & (s.push_force <= QUICK.push_max + 1e-3)) and s.push_force.max() > 0
    assert np.all((s.world >= 0) & (s.world < 4))
    gravity = np.linalg.norm(s.explicit[:, 12:15], axis=1)  # newest frame's projected gravity: a unit vector
    assert np.all(np.abs(gravity - 1) < 0.1)
    assert np.all(np.isfinite(s.value_source)) and np.all(np.isfinite(s.value_dest))
    # A success stayed up over the whole horizon; a failure fell after the switch, within the switch's step and the
    # horizon, on a step.
    assert np.all(np.isinf(s.fall_after[s.success == 1]))
    falls = s.fall_after[s.success == 0]
    assert np.all((falls > 0) & (falls <= QUICK.protocol.horizon_s + DT + 1e-4))
    np.testing.assert_allclose(falls * 30, np.round(falls * 30), atol=1e-3)
    # Both outcomes: by the contact definition a switch also fails on any touch of a non-foot body, and only then.
    touched = s.longest_touch > 0
    np.testing.assert_array_equal(s.success_contact, s.success & ~touched)
    assert np.all((s.longest_touch >= 0) & (s.longest_touch <= QUICK.protocol.horizon_s + QUICK.protocol.deadline_s))
    np.testing.assert_allclose(s.longest_touch * 30, np.round(s.longest_touch * 30), atol=1e-3)  # whole steps
    assert read(path).labelled("contact").samples.success.tolist() == s.success_contact.tolist()


def test_interrupted_collection_resumes_without_loss_or_duplicates(interrupted) -> None:
    path, before, result, seen = interrupted
    assert len(before) == 8 and result.written == 16
    after = read(path)
    for name, values in before.columns().items():  # what was written survives unchanged
        np.testing.assert_array_equal(getattr(after.samples, name)[:8], values)
    chunks = after.samples.chunk
    assert np.all(np.diff(chunks) >= 0) and chunks[0] == 0 and set(chunks[8:].tolist()) == {1, 2}
    sessions = after.info.sessions
    assert [s["first_chunk"] for s in sessions] == [0, 1] and [s["samples_at_start"] for s in sessions] == [0, 8]
    assert sessions[0]["chunk_seeds"].startswith("numpy.random.SeedSequence([0, chunk])")
    assert [s["chunk_samples"] for s in sessions] == [8, 8]
    # Each chunk draws its own numbers (seeded from the seed and the chunk index): chunks 0 and 1 differ.
    assert not np.array_equal(after.samples.phase_dest[:8], after.samples.phase_dest[8:16])
    assert [p.samples for p in seen if p.under_way == 0] == [16, 24] and seen[-1].samples_per_s > 0
    assert sum(n for _, n in seen[-1].pair_counts.values()) == 24
    assert set(seen[-1].success_rates) <= {("stand", "trot"), ("trot", "stand")}


def test_complete_file_is_left_alone_and_other_settings_are_refused(library, interrupted) -> None:
    path = interrupted[0]
    result = collect(path, library=library, gaits=GAITS, config=QUICK)
    assert result.written == 0 and result.samples == 24
    with pytest.raises(TransitionDataError, match="other settings"):
        collect(path, library=library, gaits=GAITS, config=dataclasses.replace(
            QUICK, samples=30, protocol=dataclasses.replace(QUICK.protocol, horizon_s=2.0)))


def test_pushes_are_recorded_and_pairs_can_be_restricted(library, tmp_path) -> None:
    config = dataclasses.replace(
        QUICK, samples=8, push_max=300.0, pairs=(("trot", "stand"),),
        protocol=TrialProtocol.collection(horizon_s=1.5, warmup_s=1.0, source_extra_s=1.0),
    )
    collect(tmp_path / "p.h5", library=library, gaits=GAITS, config=config)
    s = read(tmp_path / "p.h5").samples
    assert np.all(s.source == 1) and np.all(s.dest == 0)
    assert np.all((s.push_force >= 0) & (s.push_force <= 300.0 + 1e-3)) and s.push_force.max() > 0


def test_files_of_a_grown_library_are_read_as_one(tmp_path) -> None:
    def write(path, gaits, identities, batch):
        header = TransitionHeader(gaits=tuple(gaits), identities=tuple(identities), latent_dim=4,
                                  settings={"file": path.name})
        make_file(path, batch, header=header)

    old = synthetic(10)  # stand (0) <-> trot (1)
    write(tmp_path / "old.h5", ["stand", "trot"], ["s" * 64, "t" * 64], old)
    new = synthetic(6, seed=1)  # bound (0) <-> trot (1), collected after bound was added
    write(tmp_path / "new.h5", ["bound", "trot"], ["b" * 64, "t" * 64], new)
    merged = read_all([tmp_path / "old.h5", tmp_path / "new.h5"])
    assert merged.header.gaits == ("bound", "stand", "trot")
    assert merged.header.identities == ("b" * 64, "s" * 64, "t" * 64)
    s = merged.samples
    assert len(s) == 16 and merged.info.count == 16
    np.testing.assert_array_equal(s.source[:10], np.where(old.source == 0, 1, 2))
    np.testing.assert_array_equal(s.source[10:], np.where(new.source == 0, 0, 2))
    np.testing.assert_array_equal(s.latent[10:], new.latent.astype(np.float32))
    write(tmp_path / "other.h5", ["stand", "trot"], ["s" * 64, "x" * 64], synthetic(4))
    with pytest.raises(TransitionDataError, match="another 'trot' policy"):
        read_all([tmp_path / "old.h5", tmp_path / "other.h5"])


def test_samples_of_a_policy_the_library_no_longer_holds_are_left_out_and_counted(tmp_path) -> None:
    def write(path, identities, batch):
        header = TransitionHeader(gaits=("stand", "trot"), identities=identities, latent_dim=4, settings={})
        make_file(path, batch, header=header)

    old, new = synthetic(10), synthetic(6, seed=1)
    write(tmp_path / "old.h5", ("s" * 64, "t" * 64), old)  # trot retrained since: its pairs are stale
    write(tmp_path / "new.h5", ("s" * 64, "u" * 64), new)
    merged = read_all([tmp_path / "old.h5", tmp_path / "new.h5"], current={"stand": "s" * 64, "trot": "u" * 64})
    assert merged.header.gaits == ("stand", "trot") and merged.header.identities == ("s" * 64, "u" * 64)
    np.testing.assert_array_equal(merged.samples.latent, new.latent.astype(np.float32))  # every old pair has trot
    assert merged.info.count == 6 and "old.h5: 10 samples of pairs with trot left out" in merged.info.note
    with pytest.raises(TransitionDataError, match=r"no sample of .*old.h5 was collected with the library's current"):
        read_all([tmp_path / "old.h5"], current={"stand": "s" * 64, "trot": "u" * 64})


def test_collect_reports_samples_finished_inside_the_chunk_under_way(tiny_library, tmp_path, monkeypatch) -> None:
    from gaitlib.collection import chunks

    monkeypatch.setattr(chunks, "REPORT_EVERY_S", 0.0)  # a report after every control step
    seen = []
    config = dataclasses.replace(QUICK, samples=8, chunk=8)
    collect(tmp_path / "t.h5", library=tiny_library, config=config, progress=seen.append)
    inside = [p.under_way for p in seen if p.samples == 0]
    assert inside and inside[0] > 0 and inside == sorted(set(inside))  # news only, before the chunk is committed
    assert all(p.samples + p.under_way <= 8 for p in seen) and seen[-1].samples == 8
    assert seen[-1].under_way == 0


def test_a_success_chains_into_the_next_sample_without_a_reset(interrupted) -> None:
    path = interrupted[0]
    s = read(path).samples
    assert validate(path).header.settings["chain"] is True
    chained = after_failure = 0
    horizon = QUICK.protocol.horizon_s
    for chunk, world in {(int(c), int(w)) for c, w in zip(s.chunk, s.world, strict=True)}:  # each chunk starts afresh
        rows = s.select((s.chunk == chunk) & (s.world == world))
        for prev, cur in zip(range(len(rows) - 1), range(1, len(rows)), strict=True):
            # A chained switch comes the switch's step, a horizon and 0-1 s later.
            gap = rows.switch_time[cur] - rows.switch_time[prev]
            if rows.success[prev] and horizon - 1e-3 <= gap <= horizon + DT + QUICK.protocol.source_extra_s + 1e-3:
                assert rows.source[cur] == rows.dest[prev]  # the destination went on and became the next source
                chained += 1
            elif not rows.success[prev]:  # a fall resets the world: a warm-up and a source run, nothing more
                assert rows.switch_time[cur] <= QUICK.protocol.warmup_s + QUICK.protocol.source_extra_s + 1e-4
                after_failure += 1
    assert chained > 0 and after_failure > 0
