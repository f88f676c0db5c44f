"""Transition files survive any kill, have one writer at a time, and refuse damage in one line.

Kills are real SIGKILLs of forked children (a fork shares the imported modules and the tiny library, so each costs
a fraction of a second): a child patches the write primitives the writer uses (``h5py`` dataset creation,
``os.fsync``, ``os.replace``, ``Path.unlink``) to kill itself at the N-th call, then collects or appends. One test
kills inside the write of a part with ``strace``.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import signal
import subprocess
import sys
import traceback
from pathlib import Path

import h5py
import numpy as np
import pytest
from test_transitions import GAITS, HEADER, assert_same, make_file, synthetic

from gaitlib.atomic import command_line
from gaitlib.collection import CollectConfig, collect
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.meta import TrialProtocol
from gaitlib.transitions import read, read_all, schema, validate
from gaitlib.transitions import writer as writer_module
from gaitlib.transitions.writer import lock_path, open_writer

FAST = CollectConfig(
    samples=4, num_worlds=4, push_max=400.0, backend="mujoco", chunk=4,
    protocol=TrialProtocol.collection(horizon_s=0.5, warmup_s=0.1, source_extra_s=0.2),
)
"""Four worlds, one batch of four samples per commit, short cycles."""
WRITES = [(h5py.Group, "create_dataset"), (os, "fsync"), (os, "replace")]
"""What a part or index write calls: each dataset, then flush, then rename (20 calls per commit)."""


def forked(body, message: Path) -> int:
    """Run ``body()`` in a forked child; returns its pid. Exit status 0: done; 3: a one-line error (written to
    ``message``); 70: anything else (traceback in ``message``)."""
    pid = os.fork()
    if pid == 0:  # the child never returns into pytest
        code = 70
        try:
            body()
            code = 0
        except TransitionDataError as error:
            message.write_text(str(error))
            code = 3
        except BaseException:
            message.write_text(traceback.format_exc())
        finally:
            os._exit(code)
    return pid


def status(pid: int) -> int:
    """Exit code of child ``pid``, or minus the signal that killed it."""
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


def killed_at(n: int, body, tmp_path: Path, primitives=WRITES) -> int | list[str]:
    """Run ``body()`` in a child that SIGKILLs itself at the ``n``-th call of ``primitives``: returns
    ``-SIGKILL``, or (``body`` done first) the names of the calls it made, in order."""
    trace = tmp_path / f"calls-{n}.txt"

    def patched() -> None:
        calls: list[str] = []
        for owner, name in primitives:
            original = getattr(owner, name)

            def wrapper(*args, _original=original, _name=name, **kwargs):
                calls.append(_name)
                if len(calls) == n:
                    os.kill(os.getpid(), signal.SIGKILL)
                return _original(*args, **kwargs)

            setattr(owner, name, wrapper)
        body()
        trace.write_text("\n".join(calls))

    message = tmp_path / f"child-{n}.txt"
    code = status(forked(patched, message))
    assert code in (0, -signal.SIGKILL), message.read_text() if message.exists() else code
    return trace.read_text().split() if code == 0 else code


def leftovers(path: Path) -> list[str]:
    """Files beside ``path`` and in its parts folder that its index does not account for."""
    listed = {p.file for p in schema.scan(path)[0].parts}
    parts = sorted(p.name for p in schema.parts_folder(path).iterdir())
    beside = sorted(p.name for p in path.parent.iterdir() if p.name not in (path.name, schema.parts_folder(path).name))
    return [p for p in parts if p not in listed] + beside


# ------------------------------------------------------------------------------------------------------ kills
def test_a_kill_anywhere_in_a_collection_loses_at_most_the_batch_in_flight(tiny_library, tmp_path) -> None:
    path = tmp_path / "run" / "t.h5"
    collect(path, library=tiny_library, gaits=GAITS, config=FAST)
    target = dataclasses.replace(FAST, samples=20)
    # Kills at: the first write, mid-part, the part's rename, the index's rename, just after the commit, mid-part of
    # the second batch; each child resumes what the kill before it left.
    for n in (1, 7, 15, 19, 20, 27):
        before = read(path).samples
        code = killed_at(n, lambda: collect(path, library=tiny_library, gaits=GAITS, config=target), tmp_path)
        assert code == -signal.SIGKILL, f"the child finished before call {n}: {code}"
        after = validate(path)
        assert after.count - len(before) in (0, 4) and after.count < 20
        assert_same(read(path).samples.select(slice(0, len(before))), before)
    before = read(path).samples
    result = collect(path, library=tiny_library, gaits=GAITS, config=target)
    assert result.samples == 20 and result.written == 20 - len(before)
    assert_same(read(path).samples.select(slice(0, len(before))), before)
    assert leftovers(path) == []
    assert next(s["samples_at_start"] for s in validate(path).sessions) == 0


def test_a_kill_at_every_step_of_an_append_and_its_merge_keeps_every_committed_sample(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(writer_module, "FAN_IN", 4)  # the forked children merge 4 parts (fewer files to write)
    base = tmp_path / "base" / "t.h5"
    batches = [synthetic(2, start=2 * i, seed=i) for i in range(5)]
    make_file(base, *batches[:3])  # the next append makes 4 parts of one size tier: it merges them
    committed = read(base).samples

    def attempt(n: int) -> tuple[Path, int | list[str]]:
        path = Path(shutil.copytree(base.parent, tmp_path / f"n{n}")) / "t.h5"
        return path, killed_at(n, lambda: make_file(path, batches[3]), tmp_path, [*WRITES, (Path, "unlink")])

    path, calls = attempt(0)  # no kill: which calls an append makes
    assert calls.count("replace") == 4 and len(schema.scan(path)[0].parts) == 1  # part, index, merged part, index
    # Every change of primitive (first dataset of a file, its flush, its rename, the folder's flush, the first
    # removal, ...) and every seventh call.
    for n, (before, call) in enumerate(zip(["", *calls], calls, strict=False), start=1):
        if call == before and n % 7:
            continue
        path, code = attempt(n)
        assert code == -signal.SIGKILL
        samples = read(path).samples  # checks every committed part and row
        assert len(samples) in (6, 8)
        assert_same(samples.select(slice(0, 6)), committed)
        make_file(path, batches[4].select(slice(0, 1)))  # the next writer cleans up and goes on
        assert leftovers(path) == [] and validate(path).count == len(samples) + 1
        shutil.rmtree(path.parent)


@pytest.mark.skipif(
    shutil.which("strace") is None,
    reason="strace is not installed: no kill inside a part's write(2) is run, only the pure-Python kills",
)
def test_a_kill_inside_the_write_of_a_part_keeps_every_committed_sample(tiny_library, tmp_path) -> None:
    path = tmp_path / "t.h5"
    collect(path, library=tiny_library, gaits=GAITS, config=FAST)
    before = read(path).samples
    script = (
        "import dataclasses, sys; from gaitlib.library import Library; "
        "from gaitlib.collection import collect, CollectConfig; from gaitlib.meta import TrialProtocol; "
        f"fields = {dataclasses.asdict(FAST)!r}; fields['protocol'] = TrialProtocol(**fields['protocol']); "
        f"collect(sys.argv[1], library=Library(sys.argv[2]), gaits={GAITS!r}, "
        "config=dataclasses.replace(CollectConfig(**fields), samples=12))"
    )
    # HDF5 makes each part in memory and Python writes it with one write(2): killed there, in the first part's
    command = ["strace", "-f", "-qq", "-o", "/dev/null", "-e", "trace=write",
               "-e", "inject=write:signal=SIGKILL:when=1", sys.executable, "-c", script, str(path),
               str(tiny_library.root)]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")  # no other write(2) before the part's
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == -signal.SIGKILL, done.stderr
    assert_same(read(path).samples, before)
    assert collect(path, library=tiny_library, gaits=GAITS, config=dataclasses.replace(FAST, samples=8)).samples == 8
    assert_same(read(path).samples.select(slice(0, 4)), before)
    assert leftovers(path) == []


# ---------------------------------------------------------------------------------------------------- writers
def test_two_collections_of_one_new_file_one_runs_the_other_says_who_writes(tiny_library, tmp_path) -> None:
    path = tmp_path / "out" / "t.h5"
    start_r, start_w = os.pipe()
    hold_r, hold_w = os.pipe()

    def writer() -> None:
        os.read(start_r, 1)  # both start together

        def hold(progress) -> None:  # the first commit done, the winner waits until the loser has given up
            if progress.under_way == 0:  # a commit's report, not one from inside the chunk
                os.read(hold_r, 1)

        collect(path, library=tiny_library, gaits=GAITS, config=dataclasses.replace(FAST, samples=8), progress=hold)

    pids = [forked(writer, tmp_path / f"w{i}.txt") for i in range(2)]
    os.write(start_w, b"go")
    loser, code = os.wait()
    loser_code = os.waitstatus_to_exitcode(code)
    os.write(hold_w, b"xx")
    (winner,) = set(pids) - {loser}
    assert loser_code == 3 and status(winner) == 0
    message = (tmp_path / f"w{pids.index(loser)}.txt").read_text()
    assert message == f"{path} is being written by process {winner} ({command_line()})"  # a fork: pytest's line
    info = validate(path)
    assert info.count == 8 and len(info.sessions) == 1 and leftovers(path) == []


def test_a_held_lock_is_named_not_called_corrupt_and_readers_go_on(tiny_library, tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(3))
    with open_writer(path, header=HEADER) as writer:
        assert lock_path(path).read_text().splitlines() == [str(os.getpid()), command_line()]
        with pytest.raises(TransitionDataError, match="is being written by process") as caught:
            collect(path, library=tiny_library, gaits=GAITS, config=FAST)
        assert str(caught.value) == f"{path} is being written by process {os.getpid()} ({command_line()})"
        writer.append(synthetic(2, start=3))
        assert validate(path).count == 5 and len(read(path).samples) == 5
    assert not lock_path(path).exists()


# ------------------------------------------------------------------------------------------------------ damage
def test_an_empty_or_damaged_out_is_refused_in_one_line_and_left_as_it_was(tiny_library, tmp_path) -> None:
    def refused(path: Path, match: str) -> None:
        files = {p: p.read_bytes() for p in path.parent.rglob("*") if p.is_file()}
        with pytest.raises(TransitionDataError, match=match) as caught:
            collect(path, library=tiny_library, gaits=GAITS, config=FAST)
        assert "\n" not in str(caught.value)
        assert {p: p.read_bytes() for p in path.parent.rglob("*") if p.is_file()} == files

    empty = tmp_path / "empty" / "t.h5"
    empty.parent.mkdir()
    empty.touch()
    refused(empty, "is an empty file \\(0 bytes\\), not transition data")
    garbage = tmp_path / "garbage" / "t.h5"
    garbage.parent.mkdir()
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    refused(garbage, "is not an HDF5 file")
    damaged = make_file(tmp_path / "part" / "t.h5", synthetic(3))
    part = schema.parts_folder(damaged) / "part-000000000000-000000000003.h5"
    part.write_bytes(np.random.default_rng(1).bytes(part.stat().st_size))
    refused(damaged, "part-000000000000-000000000003.h5 does not match its checksum")


def test_out_of_range_gait_indices_and_negative_counts_are_one_line(tmp_path) -> None:
    path = tmp_path / "t.h5"
    batch = synthetic(4)
    batch.source[2] = 5
    part = schema.write_part(path, batch, start=0)  # as only a foreign writer would: open_writer refuses the batch
    provenance = {"created_by": "{}", "created": "2024-01-01T00:00:00+00:00"}
    schema.write_index(path, schema.TransitionIndex(header=HEADER, parts=(part,), sessions=(), provenance=provenance,
                                                    count=4))
    message = "part part-000000000000-000000000004.h5 is damaged: 'source' holds gait index 5, the file has 2 gaits"
    with pytest.raises(TransitionDataError, match=message):
        validate(path)
    with pytest.raises(TransitionDataError, match=message):
        read_all([path])
    with h5py.File(path, "r+") as f:  # as a flipped bit would: the index checksum no longer matches
        f.attrs["count"] = -3
    with pytest.raises(TransitionDataError, match=r"its index does not match its checksum"):
        validate(path)


def test_a_part_list_whose_shape_is_damaged_is_refused_without_reading_it(tmp_path) -> None:
    path = make_file(tmp_path / "t.h5", synthetic(3))
    with h5py.File(path, "r+") as f:  # as a flipped byte of the dataset's shape would: 2^40 rows, none stored
        dtype = f["parts"].dtype
        del f["parts"]
        f.create_dataset("parts", shape=(1 << 40,), dtype=dtype, chunks=(1,))
    with pytest.raises(TransitionDataError, match="index attribute or part list missing or malformed"):
        validate(path)


def test_nothing_is_created_for_a_refused_request(tiny_library, tmp_path) -> None:
    path = tmp_path / "out" / "t.h5"
    refused = (
        (dataclasses.replace(FAST, pairs=()), "no gait pairs to sample"),
        (dataclasses.replace(FAST, push_max=float("inf")), "push_max must be finite and not negative"),
    )
    for config, message in refused:
        with pytest.raises(GaitlibError, match=message):
            collect(path, library=tiny_library, gaits=GAITS, config=config)
    with pytest.raises(GaitlibError, match="must be finite"):
        TrialProtocol.collection(horizon_s=float("nan"))
    assert not path.parent.exists()
