"""What ``gaitlib drive`` and ``gaitlib run`` are given: a command shorter than a control step is driven, waypoints
a library cannot steer to are refused, what is not a small regular file is refused before it is read, no output
replaces an input, the longest run is one cap for both, and a refusal names what was given in one line."""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from cli_runner import gaitlib_quick

from gaitlib.errors import GaitlibError
from gaitlib.library.layout import default_library_dir
from gaitlib.meta.commands import MAX_INPUT_BYTES, Commands, read_commands, read_waypoints

HEADER = "time_s,forward,lateral,yaw_rate\n"


def _refused(result, line: str) -> None:
    assert (result.returncode, result.stdout, result.stderr) == (2, "", f"gaitlib: error: {line}\n")


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _bending(count: int, degrees: float, spacing: float = 0.1) -> np.ndarray:
    """``count`` waypoints ``spacing`` apart, the path bending ``degrees`` to the left at each."""
    headings = np.radians(degrees) * np.arange(count - 1)
    steps = spacing * np.column_stack([np.cos(headings), np.sin(headings)])
    return np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])


# ------------------------------------------------------------------------------------------------ waypoints
def test_a_library_that_cannot_turn_refuses_waypoints_however_small_their_bends(tmp_path) -> None:
    library = tmp_path / "library"  # the stand and the pronk turn nowhere: a closed loop could not correct its heading
    for gait in ("pronk", "stand"):
        shutil.copytree(default_library_dir() / gait, library / gait)
    text = "x,y\n" + "".join(f"{x!r},{y!r}\n" for x, y in _bending(13, 0.9).tolist())
    plot = tmp_path / "drive.png"
    result = gaitlib_quick("drive", "--waypoints", str(_write(tmp_path / "w.csv", text)), "--plot", str(plot),
                           "--library", str(library))
    _refused(result, "waypoints need a skill that turns, in place or going ahead, to aim at them again as the robot "
             "drifts; the library holds none")
    assert not plot.exists()


def test_a_waypoint_s_distance_is_measured_from_the_first(tmp_path) -> None:
    far_away = read_waypoints(_write(tmp_path / "far.csv", "x,y\n5000,0\n5001,0\n"))
    assert far_away.tolist() == [[5000.0, 0.0], [5001.0, 0.0]]
    with pytest.raises(GaitlibError, match=r"waypoint 3 lies 1131\.4 m from the first, where the robot starts"):
        read_waypoints(_write(tmp_path / "corner.csv", "x,y\n0,0\n800,0\n800,800\n"))


# ------------------------------------------------------------------------------- commands shorter than a step
def test_a_command_shorter_than_a_control_step_is_driven(tmp_path) -> None:
    commands = Commands(time_s=np.array([0.0, 0.25, 0.26, 0.3]),
                        velocity=np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 1.0], [0.5, 0.0, 0.0]]))
    path = commands.path(1 / 30)  # no control step ends within 0.25-0.26 s: the path only carries its turn on
    assert path[-1] == pytest.approx([0.125 + 0.02 * math.cos(0.01), 0.02 * math.sin(0.01), 0.01])
    csv = _write(tmp_path / "c.csv", HEADER + "0,0.7,0,0\n0.25,0.71,0,0\n0.26,0.7,0,0\n0.3,0,0,0\n")
    result = gaitlib_quick("drive", "--commands", str(csv), "--plot", str(tmp_path / "d.png"), "--backend",
                           "mujoco", "--json", "--no-guard")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [row["until_s"] for row in report["commands"]] == [0.25, 0.26, 0.3]
    assert report["commands"][1]["achieved"] is None  # in force for no step
    assert len(report["path"]) == 10 and (tmp_path / "d.png").exists()


@pytest.mark.parametrize(
    ("flag", "name", "text", "line"),
    [
        ("--commands", "c.csv", HEADER + "0,0.7,0,0\n1e-9,0,0,0\n",
         "{path}: the drive ends at 1e-09 s, less than half a control step (1/30 s): there is nothing to drive"),
        ("--waypoints", "w.csv", "x,y\n1,0\n1.2,0\n0.9,0.1\n",
         "every waypoint lies within 0.2 m of the first, where the robot starts: all are reached before the first "
         "step, there is nothing to drive"),
    ],
)
def test_a_drive_shorter_than_half_a_step_is_refused_before_the_simulation(tmp_path, flag, name, text, line) -> None:
    path = _write(tmp_path / name, text)
    _refused(gaitlib_quick("drive", flag, str(path), "--plot", str(tmp_path / "d.png"), "--no-guard"),
             line.format(path=path))
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


# ---------------------------------------------------------------------------------------- what is read at all
def test_a_device_a_pipe_a_folder_and_a_large_file_are_refused_before_they_are_read(tmp_path) -> None:
    plot = ["--plot", str(tmp_path / "d.png")]
    _refused(gaitlib_quick("drive", "--waypoints", str(tmp_path), *plot),
             f"{tmp_path} is a folder; a waypoint list is read from a regular file")
    large = tmp_path / "large.csv"
    large.write_text(HEADER + "0,0.7,0,0\n" * (MAX_INPUT_BYTES // 10) + "1,0,0,0\n")
    _refused(gaitlib_quick("drive", "--commands", str(large), *plot),
             f"{large} is larger than 1 MiB, more than a command timeline of any drive holds")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)

    def write() -> None:
        with contextlib.suppress(BrokenPipeError):  # let go below, unread
            fifo.write_text(HEADER + "0,0.7,0,0\n0.1,0,0,0\n")

    writer = threading.Thread(target=write, daemon=True)
    writer.start()  # a reader that opened the pipe would get a timeline; one that waits for it would hang
    try:
        _refused(gaitlib_quick("drive", "--commands", str(fifo), *plot),
                 f"{fifo} is a named pipe; a command timeline is read from a regular file")
    finally:
        os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))  # lets a writer still waiting go
        writer.join(timeout=10)
    _refused(gaitlib_quick("drive", "--commands", "/dev/zero", *plot),  # read, it fills the memory
             "/dev/zero is a device; a command timeline is read from a regular file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "large.csv"]


def test_a_byte_order_mark_is_read_and_a_header_shows_what_it_holds(tmp_path) -> None:
    marked = tmp_path / "marked.csv"
    marked.write_bytes(b"\xef\xbb\xbf" + (HEADER + "0,0.7,0,0\n0.5,0,0,0\n").encode())
    commands = read_commands(marked)
    assert commands.time_s.tolist() == [0.0, 0.5] and commands.velocity.tolist() == [[0.7, 0.0, 0.0]]
    hidden = _write(tmp_path / "hidden.csv", "time_s\u200b,forward,lateral,yaw_rate\n0,0.7,0,0\n0.5,0,0,0\n")
    _refused(gaitlib_quick("drive", "--commands", str(hidden)),
             f"{hidden}: the header is 'time_s\\u200b,forward,lateral,yaw_rate'; a command timeline needs "
             "'time_s,forward,lateral,yaw_rate'")


def test_values_are_named_as_given_and_a_huge_one_is_refused_without_warnings(tmp_path) -> None:
    late = _write(tmp_path / "late.csv", HEADER + "0,0.7,0,0\n600.0000001,0,0,0\n")
    _refused(gaitlib_quick("drive", "--commands", str(late)),
             f"{late}: the drive ends at 600.0000001 s, longer than the longest run, 600 s")
    huge = _write(tmp_path / "huge.csv", HEADER + "0,1e308,0,0\n1,0,0,0\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow warnings, before the refusal, would fail here
        result = gaitlib_quick("drive", "--commands", str(huge))
    _refused(result, f"{huge}: line 2 holds 1e308, larger than any drive takes (at most 1000000 in size)")
    _refused(gaitlib_quick("drive", "--commands", str(late), "--seed", str(2**70)),
             f"--seed must be a whole number in [0, 4294967295], got {2**70}")


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["eval", "stand", "--episodes", "2.5"], "--episodes must be a whole number in [1, 65536], got 2.5"),
        (["eval", "stand", "--episodes", "two"], "--episodes must be a whole number in [1, 65536], got 'two'"),
        (["eval", "stand", "--seconds", "1e400"], "--seconds must be a finite number in (0, 600] s, got 1e400"),
        (["drive", "--seed", "0.5"], "--seed must be a whole number in [0, 4294967295], got 0.5"),
        (["run", "--action-delay", "1.5"], "--action-delay must be a whole number in [0, 10], got 1.5"),
        (["run", "--guard-margin", "abc"], "--guard-margin must be a finite number in [0, 1), got 'abc'"),
        (["drive", "--guard-margin", "1"], "--guard-margin must be a finite number in [0, 1), got 1"),
        (["survival", "fit", "x.npz", "--margin", "-0.1"], "--margin must be a finite number in [0, 1), got -0.1"),
    ],
)
def test_a_number_option_given_what_it_does_not_take_is_one_line(args, line) -> None:
    _refused(gaitlib_quick(*args), line)


def test_a_whole_number_option_takes_a_whole_number_however_written() -> None:
    from gaitlib.cli.options import Bounds, Number

    samples = Number("--samples", Bounds(low=1, high=1e8, whole=True))
    assert samples("2e6") == 2_000_000 and isinstance(samples("2e6"), int) and samples(" 12 ") == 12
    assert samples(5) == 5  # a default, as declared


# ------------------------------------------------------------------------------------------- outputs apart
def test_no_output_of_a_drive_replaces_what_it_reads(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    text = HEADER + "0,0.7,0,0\n0.2,0,0,0\n"
    source = _write(tmp_path / "in.csv", text)
    (tmp_path / "link.csv").symlink_to(source)
    os.link(source, tmp_path / "hard.csv")
    (tmp_path / "sub").mkdir()
    for plot in ("in.csv", "link.csv", "sub/../in.csv", str(source), "hard.csv"):
        _refused(gaitlib_quick("drive", "--commands", "in.csv", "--plot", plot), f"--plot {plot} is the input "
                 "--commands in.csv: writing it would replace what the command reads; give --plot another path")
    _refused(gaitlib_quick("drive", "--commands", "in.csv", "--plot", "d.mp4", "--video", "./d.mp4"),
             "--plot and --video both name d.mp4; give each its own path")
    shipped = default_library_dir()
    _refused(gaitlib_quick("drive", "--commands", "in.csv", "--plot", str(shipped / "trot" / "x.png")),
             f"--plot {shipped / 'trot' / 'x.png'} lies in the library {shipped}, which the command reads; give "
             "--plot a path outside it")
    _refused(gaitlib_quick("run", "--library", str(shipped), "--video", str(shipped / "run.mp4")),
             f"--video {shipped / 'run.mp4'} lies in --library {shipped}, which the command reads; give --video a "
             "path outside it")
    assert source.read_text() == text and not (shipped / "trot" / "x.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hard.csv", "in.csv", "link.csv", "sub"]


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="no /proc file system")
def test_a_folder_that_refuses_a_new_file_is_refused_before_the_drive(tmp_path) -> None:
    commands = _write(tmp_path / "c.csv", HEADER + "0,0.7,0,0\n0.2,0,0,0\n")
    _refused(gaitlib_quick("drive", "--commands", str(commands), "--plot", "/proc/x.png"),
             "--plot /proc/x.png cannot be written: the folder /proc is not writable")


# ------------------------------------------------------------------------------------------- the longest run
def test_a_run_longer_than_a_drive_may_be_is_refused_before_any_work(tmp_path, monkeypatch) -> None:
    def no_work(*args, **kwargs):
        raise AssertionError("the command simulated before refusing")

    monkeypatch.setattr("gaitlib.meta.episode.make_backend", no_work)
    chain = ",".join(["stand", "trot"] * 50)
    plot = tmp_path / "run.png"
    _refused(gaitlib_quick("run", "--from", "trot", "--to", chain, "--hold", "600", "--no-guard", "--plot", str(plot)),
             "a run of 100 request(s) can last 60202 s (the first request at 2 s, then for each gait the switch's "
             "deadline of 2 s and the hold of 600 s), longer than the longest run, 600 s")
    late = _write(tmp_path / "late.csv", HEADER + "0,0.7,0,0\n601,0,0,0\n")
    _refused(gaitlib_quick("drive", "--commands", str(late), "--no-guard", "--plot", str(plot)),
             f"{late}: the drive ends at 601 s, longer than the longest run, 600 s")
    assert not plot.exists()
