"""The single-push curve (gaitlib eval --impulses): one push per episode at a random phase and direction, the fall
rate per impulse with its interval and per direction."""

from __future__ import annotations

import json

from cli_runner import gaitlib_quick

from gaitlib.envs import EnvConfig
from gaitlib.evaluation import SECTORS, PushPoint, single_push_curve
from gaitlib.library import Library
from gaitlib.library.layout import shipped_library_dir


def test_a_harder_push_fells_more_and_every_direction_is_hit() -> None:
    library = Library(shipped_library_dir())
    stand = library.entry("stand")
    points = single_push_curve(
        stand.policy, stand.clip, env_cfg=library.shared_policy_settings(["stand"]).env_config(EnvConfig()),
        impulses=(0.0, 60.0), episodes=24, backend="mujoco", seed=0,
    )
    quiet, hard = points
    assert (quiet.impulse_ns, hard.impulse_ns) == (0.0, 60.0) and hard.force_n == 60.0 / (3 / 30)
    assert quiet.fell == 0 and hard.fell > quiet.fell  # 60 N s: 4.8 m/s for the A1
    assert hard.fall_ci95[0] <= hard.fall_rate <= hard.fall_ci95[1]
    assert sum(k for _, k in hard.by_sector.values()) == 24 and set(hard.by_sector) == set(SECTORS)
    assert all(k > 0 for _, k in hard.by_sector.values())
    assert PushPoint.from_dict(json.loads(json.dumps(hard.as_dict()))) == hard  # a stored curve reads back whole


def test_the_command_prints_the_curve_and_plots_it(tmp_path) -> None:
    plot = tmp_path / "push.png"
    result = gaitlib_quick("eval", "stand", "--impulses", "0,6", "--episodes", "4", "--backend", "mujoco",
                           "--plot", str(plot), "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [p["impulse_ns"] for p in report["points"]] == [0.0, 6.0] and report["gait"] == "stand"
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    refused = gaitlib_quick("eval", "stand", "--impulses", "0:900:100")
    assert refused.returncode == 2 and "--impulses" in refused.stderr and refused.stderr.count("\n") == 1
