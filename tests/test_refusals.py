"""Bad input is refused in one line (exit code 2) before any work and before any file is written: numeric options
out of range or not finite, option texts that name nothing, damaged checkpoints and switching files, a resumed
benchmark with other settings."""

from __future__ import annotations

import json
import shutil
import sys

import pytest
import torch
from cli_runner import gaitlib_quick
from conftest import write_foreign_json

from gaitlib.library import Library, default_library_dir
from gaitlib.robots.a1.constants import JOINT_NAMES, MJCF_PATH


def _refused(result, line: str) -> None:
    assert (result.returncode, result.stdout, result.stderr) == (2, "", f"gaitlib: error: {line}\n")


# Refused while the command line is parsed: the option, its range with its unit, and the value given.
PARSE_REFUSALS = [
    (["collect", "--push-max", "nan"], "--push-max must be a finite number in [0, 2000] N, got nan"),
    (["collect", "--push-max", "inf"], "--push-max must be a finite number in [0, 2000] N, got inf"),
    (["collect", "--push-max", "1e9"], "--push-max must be a finite number in [0, 2000] N, got 1000000000"),
    (["collect", "--samples", "nan"], "--samples must be a whole number in [1, 100000000], got nan"),
    (["collect", "--samples", "inf"], "--samples must be a whole number in [1, 100000000], got inf"),
    (["collect", "--samples", "2.5"], "--samples must be a whole number in [1, 100000000], got 2.5"),
    (["collect", "--horizon", "nan"], "--horizon must be a finite number in (0, 60] s, got nan"),
    (["collect", "--horizon", "inf"], "--horizon must be a finite number in (0, 60] s, got inf"),
    (["collect", "--worlds", "100000"], "--worlds must be a whole number in [1, 65536], got 100000"),
    (["collect", "--seed", "-1"], "--seed must be a whole number in [0, 4294967295], got -1"),
    (["fit", "--epochs", "0"], "--epochs must be a whole number in [1, 1000000], got 0"),
    (["benchmark", "--samples", "0"], "--samples must be a whole number in [1, 1000000], got 0"),
    (["benchmark", "--worlds", "0"], "--worlds must be a whole number in [1, 65536], got 0"),
    (["benchmark", "--action-delay", "11"], "--action-delay must be a whole number in [0, 10], got 11"),
    (["benchmark", "--action-delay", "-1"], "--action-delay must be a whole number in [0, 10], got -1"),
    (["benchmark", "--motor-strength", "0"], "--motor-strength must be a finite number in (0, 10], got 0"),
    (["benchmark", "--motor-strength", "nan"], "--motor-strength must be a finite number in (0, 10], got nan"),
    (["collect", "--workers", "0"], "--workers must be a whole number in [1, 4096], got 0"),
    (["benchmark", "--workers", "0"], "--workers must be a whole number in [1, 4096], got 0"),
    (["collect", "--chunk", "0"], "--chunk must be a whole number in [1, 10000000], got 0"),
    (["run", "--hold", "inf"], "--hold must be a finite number in (0, 600] s, got inf"),
    (["run", "--push", "nan"], "--push must be a finite number in [0, 2000] N, got nan"),
    (["run", "--push", "-100"], "--push must be a finite number in [0, 2000] N, got -100"),
    (["eval", "stand", "--seconds", "nan"], "--seconds must be a finite number in (0, 600] s, got nan"),
    (["eval", "stand", "--episodes", "0"], "--episodes must be a whole number in [1, 65536], got 0"),
    (["throughput", "sim", "--seconds", "nan"], "--seconds must be a finite number in (0, 3600] s, got nan"),
    (["throughput", "sim", "--seconds", "-1"], "--seconds must be a finite number in (0, 3600] s, got -1"),
    (["throughput", "collect", "--seconds", "0"], "--seconds must be a finite number in (0, 3600] s, got 0"),
    (["train", "stand", "--checkpoint-every", "0"], "--checkpoint-every must be a whole number in [1, 1000000], got 0"),
    (["train", "stand", "--minutes", "-1"], "--minutes must be a finite number in (0, 100000] min, got -1"),
    (["train", "stand", "--eval-episodes", "0"], "--eval-episodes must be a whole number in [1, 65536], got 0"),
    (["train", "stand", "--iterations", "0"], "--iterations must be a whole number in [1, 1000000], got 0"),
    (["train", "stand", "--worlds", "0"], "--worlds must be a whole number in [1, 65536], got 0"),
    (["train", "stand", "--eval-seconds", "0"], "--eval-seconds must be a finite number in (0, 600] s, got 0"),
]


@pytest.mark.parametrize(("args", "line"), PARSE_REFUSALS, ids=[" ".join(a) for a, _ in PARSE_REFUSALS])
def test_a_numeric_option_out_of_range_is_refused_before_anything_is_written(args, line, tmp_path) -> None:
    # Every path a command may write under the test folder; none may appear.
    outputs = {
        "collect": ["--out", str(tmp_path / "new" / "x.h5")],
        "benchmark": ["--out", str(tmp_path / "bench")],
        "run": ["--plot", str(tmp_path / "run.png")],
        "train": ["--library", str(tmp_path / "lib"), "--run-dir", str(tmp_path / "runs")],
    }.get(args[0], [])
    _refused(gaitlib_quick(*args, *outputs), line)
    assert list(tmp_path.iterdir()) == []


def test_an_existing_output_keeps_its_bytes_when_an_option_is_refused(tmp_path) -> None:
    out = tmp_path / "k.h5"
    out.write_bytes(b"not touched")
    _refused(gaitlib_quick("collect", "--out", str(out), "--horizon", "nan"), "--horizon must be a finite number in "
             "(0, 60] s, got nan")
    assert out.read_bytes() == b"not touched"


def test_more_worlds_than_the_memory_holds_are_refused(monkeypatch, tmp_path) -> None:
    monkeypatch.setattr("gaitlib.cli.options._available_bytes", lambda: 2**30)
    out = tmp_path / "x.h5"
    result = gaitlib_quick("collect", "--worlds", "2048", "--backend", "mujoco", "--out", str(out))
    _refused(result, "--worlds 2048 needs about 2.0 GiB (1 MiB per MuJoCo world) but 1.0 GiB is available; "
             "use fewer worlds")
    assert not out.exists()


@pytest.mark.parametrize(
    ("magnitudes", "line"),
    [
        ("nan", "--magnitudes must be a finite number in [0, 2000] N, got nan"),
        ("inf", "--magnitudes must be a finite number in [0, 2000] N, got inf"),
        ("0:1e10:1", "--magnitudes must be a finite number in [0, 2000] N, got 10000000000"),
        ("0:2000:1e-6", "--magnitudes '0:2000:1e-6': give 1 to 1000 values"),  # counted, never built
        (
            "50,50.0000001",
            "push magnitudes 50.0 N and 50.0000001 N are one cell (magnitudes are resolved to 0.001 N); give each once",
        ),
    ],
)
def test_bad_push_magnitudes_are_refused(magnitudes, line, tmp_path) -> None:
    out = tmp_path / "bench"
    _refused(gaitlib_quick("benchmark", "--strategies", "random", "--magnitudes", magnitudes, "--out", str(out)), line)
    assert not out.exists()


def test_a_robot_model_missing_not_an_a1_or_on_newton_is_refused_in_one_line(tmp_path) -> None:
    out = ["--out", str(tmp_path / "bench")]
    missing = (tmp_path / "missing.xml").resolve()
    _refused(gaitlib_quick("benchmark", "--robot", str(missing), *out),
             f"cannot read robot model {missing}: No such file or directory")
    box = (tmp_path / "box.xml").resolve()
    box.write_text('<mujoco><worldbody><geom name="floor" type="plane" size="1 1 .1"/>'
                   '<body pos="0 0 1"><freejoint/><geom size=".1"/></body></worldbody></mujoco>')
    _refused(gaitlib_quick("benchmark", "--robot", str(box), *out),
             f"robot model {box} has no hinge joint {', '.join(JOINT_NAMES)} (an A1 names its joints FR_hip_joint ... "
             "RL_calf_joint)")
    _refused(gaitlib_quick("benchmark", "--robot", str(MJCF_PATH), "--backend", "newton", *out),
             "--robot and --motor-strength run on the mujoco backend only, not on 'newton'; use --backend mujoco")
    _refused(gaitlib_quick("benchmark", "--motor-strength", "0.8", "--backend", "newton", *out),
             "--robot and --motor-strength run on the mujoco backend only, not on 'newton'; use --backend mujoco")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["box.xml"]


def test_option_texts_that_name_nothing_are_refused(tmp_path) -> None:
    out = tmp_path / "x.h5"
    _refused(gaitlib_quick("collect", "--pairs", ",,,", "--out", str(out)),
             "--pairs ',,,' names no pair; give pairs like trot-stand,pace-stand")
    _refused(gaitlib_quick("collect", "--pairs", "trot-", "--out", str(out)),
             "--pairs 'trot-': 'trot-' is not a pair; give pairs like trot-stand")
    _refused(gaitlib_quick("benchmark", "--strategies", "random,random", "--out", str(tmp_path / "b")),
             "a strategy is given twice in random, random; give each once")
    _refused(gaitlib_quick("run", "--request-at", "nan", "--plot", str(tmp_path / "run.png")),
             "--request-at must be a finite number in [0, 600] s, got nan")
    assert list(tmp_path.iterdir()) == []


def test_resume_from_a_truncated_or_foreign_checkpoint_is_one_line(tmp_path) -> None:
    latest = tmp_path / "runs" / "checkpoints" / "latest.pt"
    latest.parent.mkdir(parents=True)
    args = ["train", "stand", "--preset", "tiny", "--resume", "--library", str(tmp_path / "lib"),
            "--run-dir", str(tmp_path / "runs")]
    torch.save({"actor_state_dict": {"w": torch.zeros(3)}, "iter": 5, "infos": {"gait": "stand"}}, latest)
    whole = latest.read_bytes()
    _refused(gaitlib_quick(*args), f"checkpoint {latest} is not a gaitlib training checkpoint (no complete run "
             f"record) and cannot be resumed; give this run its own --run-dir, or remove {latest} to start over in "
             "its folder")
    latest.write_bytes(whole[: len(whole) // 2])
    _refused(gaitlib_quick(*args), f"checkpoint {latest} is unreadable (truncated, or not a plain torch "
             f"checkpoint) and cannot be resumed; give this run its own --run-dir, or remove {latest} to start over "
             "in its folder")
    assert not (tmp_path / "lib").exists()


@pytest.fixture(scope="module")
def shipped_copy(tmp_path_factory) -> Library:
    """A copy of the shipped library, its switching files to damage."""
    root = tmp_path_factory.mktemp("refusals") / "library"
    shutil.copytree(default_library_dir(), root)
    return Library(root)


def _benchmark(library: Library, strategy: str, out) -> object:
    return gaitlib_quick("benchmark", "--strategies", strategy, "--library", str(library.root), "--out", str(out))


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda tmt: tmt.pop("thresholds"), "missing 'thresholds'"),
        (lambda tmt: tmt.pop("library_identities"), "missing 'library_identities'"),
        (lambda tmt: tmt["thresholds"].pop("tmt-value"), "missing 'tmt-value'"),
        (lambda tmt: tmt.update(successes=tmt["successes"][:1], counts=tmt["counts"][:1]), "a table of shape "),
        (lambda tmt: tmt["successes"][0].pop(), "'successes' is not a table of numbers"),
        (lambda tmt: tmt["thresholds"]["tmt"].update({"trot-stand": float("nan")}), "a threshold or typical value"),
    ],
    ids=["thresholds", "identities", "one-strategy", "short", "ragged", "nan"],
)
def test_a_damaged_tmt_is_one_line(shipped_copy, damage, why, tmp_path) -> None:
    path = shipped_copy.tmt_path
    original = path.read_text()
    tmt = json.loads(original)
    damage(tmt)
    write_foreign_json(path, tmt)  # its own checksum matches
    shipped_copy.write_checksums(shipped_copy.switching_dir)
    try:
        result = _benchmark(shipped_copy, "tmt", tmp_path / "bench")
    finally:
        path.write_text(original)
        shipped_copy.write_checksums(shipped_copy.switching_dir)
    assert result.returncode == 2 and result.stdout == "" and len(result.stderr.splitlines()) == 1
    assert result.stderr.startswith(f"gaitlib: error: TMT {path} is damaged ({why}")
    assert result.stderr.endswith("); run gaitlib fit\n")
    assert not (tmp_path / "bench").exists()


def test_a_net_without_identities_is_one_line(shipped_copy, tmp_path) -> None:
    path = shipped_copy.net_path
    original = path.read_bytes()
    saved = torch.load(path, weights_only=True)
    del saved["metadata"]["library_identities"]
    torch.save(saved, path)
    shipped_copy.write_checksums(shipped_copy.switching_dir)  # as a foreign writer would: the checksums agree
    try:
        result = _benchmark(shipped_copy, "net", tmp_path / "bench")
    finally:
        path.write_bytes(original)
        shipped_copy.write_checksums(shipped_copy.switching_dir)
    _refused(result, f"transition-net {path} is damaged: no library identity for each of its gaits")


def test_a_resumed_benchmark_with_other_worlds_is_refused(tmp_path) -> None:
    out = tmp_path / "bench"
    args = ["benchmark", "--strategies", "random", "--magnitudes", "0", "--samples", "1", "--pairs", "trot-stand",
            "--backend", "mujoco", "--out", str(out), "--json"]
    first = gaitlib_quick(*args, "--worlds", "2")
    assert first.returncode == 0, first.stderr
    before = (out / "results.json").read_bytes()
    _refused(gaitlib_quick(*args, "--worlds", "3"),
             f"{out} holds a benchmark with other settings (num_worlds); use another --out or delete it")
    assert (out / "results.json").read_bytes() == before


@pytest.mark.parametrize("command", ["collect", "benchmark"])
def test_ray_options_are_refused_in_one_line_without_ray_or_without_each_other(command, tmp_path, monkeypatch):
    out = ["--out", str(tmp_path / "new" / ("x.h5" if command == "collect" else "bench"))]
    monkeypatch.setitem(sys.modules, "ray", None)  # as where Ray is not installed: `import ray` fails
    _refused(gaitlib_quick(command, "--ray", "--workers", "2", *out),
             '--ray needs Ray, which is not installed: pip install -e ".[cluster]"')
    _refused(gaitlib_quick(command, "--workers", "2", *out),
             "--workers needs --ray (without it the job runs in this process)")
    _refused(gaitlib_quick(command, "auto", *out), "unexpected argument 'auto' (a Ray address goes after --ray)")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["train", "stand", "--terminate", "legs"], "--terminate takes trunk or contact, got 'legs'"),
        (["eval", "stand", "--falls", "legs"], "--falls takes trunk or contact, got 'legs'"),
        (["benchmark", "--falls", "Trunk"], "--falls takes trunk or contact, got 'Trunk'"),
    ],
)
def test_a_definition_of_a_fall_other_than_trunk_or_contact_is_refused_while_parsing(args, line, tmp_path) -> None:
    """What a fall is, is checked once, as the command line is parsed; below it the definition is a
    :class:`gaitlib.defaults.Falls`, which holds no other."""
    outputs = {"benchmark": ["--out", str(tmp_path / "bench")],
               "train": ["--library", str(tmp_path / "lib"), "--run-dir", str(tmp_path / "runs")]}.get(args[0], [])
    _refused(gaitlib_quick(*args, *outputs), line)
    assert list(tmp_path.iterdir()) == []
