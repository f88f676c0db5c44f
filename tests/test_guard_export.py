"""The guard in deployable form: examples/deploy_guard.py, from the folder gaitlib survival export writes, reads
what gaitlib's guard reads and decides what it decides; an estimate that needs the critic is refused."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from gaitlib.envs import EnvConfig
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import SECTORS
from gaitlib.library import Library
from gaitlib.meta import load_switching
from gaitlib.sim import make_backend
from gaitlib.strategies.guard_export import export_guard
from gaitlib.strategies.survival import SurvivalEstimate, SurvivalNet, save_survival
from tests.conftest import copy_library

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "deploy_guard.py"


def _estimate(setup, inputs: tuple[str, ...], margin: float) -> SurvivalEstimate:
    """An estimate of random weights (a real MLP, so that the export carries its weights and standardization)."""
    torch.manual_seed(0)
    latent = setup.entries[0].policy.latent_dim
    dim = len(setup.gaits) + latent + 2 + (1 if "value" in inputs else 0) + (3 if "imu" in inputs else 0)
    net = SurvivalNet(dim)
    net.mean.normal_()
    net.std.uniform_(0.5, 2.0)
    platt = {k: (0.8 + 0.1 * k, -0.2 + 0.3 * k) for k in range(len(setup.gaits))}
    return SurvivalEstimate(setup.gaits, setup.resources.library.identities(setup.gaits), inputs, 0.5, margin,
                            platt, net.eval())


def test_the_doc_shows_the_example_verbatim() -> None:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "deploying.md").read_text(), flags=re.DOTALL)
    assert EXAMPLE.read_text() in blocks


def test_the_robot_loop_reads_and_decides_as_the_guard(switching_library, tmp_path):
    from gaitlib.meta.guard import Guard
    from gaitlib.strategies import get_strategy

    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    estimate = _estimate(setup, ("latent", "phase", "imu"), margin=0.0)
    estimate.floor = 0.3  # the robot catches below it as the guard does
    estimate.info["armed_from_s"] = 2 / 30  # the first two control steps of an episode: no catch on either side
    table = {"stand": {"front": "trot", "back": "trot"}, "trot": dict.fromkeys(SECTORS, "stand")}
    estimate.info["catches"] = {"catch_into": table}  # a catch table by direction travels with it
    (tmp_path / "states.h5").write_bytes(b"random")
    save_survival(library, estimate, data=tmp_path / "states.h5")
    run = subprocess.run([sys.executable, "-m", "gaitlib.cli", "survival", "export", "--out", str(tmp_path / "guard"),
                          "--library", str(library.root)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    spec = importlib.util.spec_from_file_location("deploy_guard", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    robot = module.RobotGuard(tmp_path / "guard")
    assert robot.spec["catch_into"] == table and robot.spec["armed_from_s"] == 2 / 30 and robot.spec["floor"] == 0.3
    guard = Guard(estimate, get_strategy("net-lookahead", setup.resources))
    sim = make_backend("mujoco", num_worlds=3)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=5.0), seed=1)
        env.reset_worlds(torch.arange(3), gait=torch.tensor([0, 1, 1]))
        ctl = setup.controller(env, "net-lookahead")
        fired = []
        for step in range(4):
            ids = torch.arange(3)
            reading = guard.read(env, ctl.policies, ids, ctl.candidates)
            fires = guard.fires(reading)
            fired.append(bool(fires.any()))
            assert not (fires & ~reading.armed).any() and (step >= 2 or not reading.armed.any())  # (a fall restarts)
            obs = env.get_observations().policy.cpu().numpy()
            imu = env.trunk_acceleration.cpu().numpy()
            for w in range(3):
                gait = setup.gaits[int(env.gait[w])]
                stay, offers = robot.read(gait, obs[w], float(env.phase[w]), imu[w])
                assert stay == pytest.approx(float(reading.stay[w]), abs=1e-4)
                if table[gait].get(robot.sector(imu[w])) is None:  # pushed where the table has no catch
                    assert reading.offer[w].isnan().all()
                for dest, (offer, phase) in offers.items():
                    n = setup.gait_index(dest)
                    if not reading.offer[w, n].isnan():
                        assert offer == pytest.approx(float(reading.offer[w, n]), abs=1e-4)
                    assert phase == pytest.approx(float(reading.phase[w, n]))
                time_s = float(env.episode_length_buf[w]) * env.dt
                decided = robot.decide(gait, obs[w], float(env.phase[w]), time_s, imu[w])
                assert (decided is not None) == bool(fires[w])
                if decided is not None:
                    n = int(reading.best()[1][w])
                    assert decided == (setup.gaits[n], pytest.approx(float(reading.phase[w, n])))
            ctl.step()
    finally:
        sim.close()
    assert fired[:2] == [False, False] and any(fired[2:])  # unarmed, then catches (a margin of 0)


def test_an_estimate_reading_the_critic_is_refused(switching_library, tmp_path):
    setup = load_switching(switching_library)
    with pytest.raises(GaitlibError, match="privileged"):
        export_guard(tmp_path / "guard", policies=[e.policy for e in setup.entries],
                     estimate=_estimate(setup, ("latent", "phase", "value"), margin=0.1), net=setup.resources.net,
                     calibration=setup.resources.calibration)
    assert not (tmp_path / "guard").exists()
