"""The guard in deployable form: examples/deploy_guard.py, from the folder gaitlib survival export writes, reads
what gaitlib's guard reads and decides what it decides, and reads a trunk calm where gaitlib does (the hold after a
catch into a catch skill); an estimate that needs the critic is refused."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from gaitlib.envs import EnvConfig
from gaitlib.envs.catch import CALM_RATE_RAD_S, CALM_SPEED_M_S, CALM_TILT_DEG, CALM_WAIT_S, is_calm
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import SECTORS
from gaitlib.library import Library
from gaitlib.meta import load_switching
from gaitlib.rotations import quat_multiply, quat_rotate_inverse
from gaitlib.sim import make_backend
from gaitlib.strategies.base import SwitchQuery
from gaitlib.strategies.guard_export import export_guard
from gaitlib.strategies.survival import SurvivalEstimate, SurvivalNet, save_survival
from tests.conftest import copy_library

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "deploy_guard.py"


SCORES = 1e-5
"""How near the robot's scores (ONNX Runtime, float32) come to the guard's (torch, float32): its survival estimate and
offers, probabilities (they agree to 1 or 2 float32 steps, about 1e-7, where this was written; the two runtimes sum in
their own order, which follows the processor). A decision is compared only where the scores it weighs lie further
than twice this from its threshold, where no score within this could turn it."""


def _clear_of_sector_edges(acceleration) -> bool:
    """The push's direction lies further than 1e-4 rad from an edge between two of SECTORS (the robot's NumPy and
    the guard's torch may put a push on an edge in either)."""
    quarters = math.atan2(float(acceleration[1]), float(acceleration[0])) / (math.pi / 2)  # edges at k + 0.5
    return abs(quarters - math.floor(quarters) - 0.5) > 1e-4 / (math.pi / 2)


def _best_by(guard, reading, env, w: int, n: int, candidates: torch.Tensor) -> float:
    """By how much the guard's best destination phase of world ``w`` into gait ``n`` beats the next best."""
    query = SwitchQuery(source=env.gait[w : w + 1], dest=torch.tensor([n]), phase_source=env.phase[w : w + 1],
                        latent=reading.latent[w : w + 1], candidates=candidates)
    top = guard.scorer.scores(query)[0].topk(2).values
    return float(top[0] - top[1])


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


def _robot_guard(folder: Path):
    """examples/deploy_guard.py's RobotGuard on ``folder``."""
    spec = importlib.util.spec_from_file_location("deploy_guard", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.RobotGuard(folder)


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
    robot = _robot_guard(tmp_path / "guard")
    assert robot.spec["catch_into"] == table and robot.spec["armed_from_s"] == 2 / 30 and robot.spec["floor"] == 0.3
    assert robot.spec["catchers"] == [] and not robot.holds_until_calm("stand")  # the tiny library has no catch skill
    guard = Guard(estimate, get_strategy("net-lookahead", setup.resources))
    sim = make_backend("mujoco", num_worlds=3)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=5.0), seed=1)
        env.reset_worlds(torch.arange(3), gait=torch.tensor([0, 1, 1]))
        ctl = setup.controller(env, "net-lookahead")
        fired, decisions, choices = [], 0, 0
        for step in range(4):
            ids = torch.arange(3)
            reading = guard.read(env, ctl.policies, ids, ctl.candidates)
            fires = guard.fires(reading)
            fired.append(bool(fires.any()))
            assert not (fires & ~reading.armed).any() and (step >= 2 or not reading.armed.any())  # (a fall restarts)
            obs = env.get_observations().policy.cpu().numpy()
            imu = env.trunk_acceleration.cpu().numpy()
            best, best_gait = reading.best()
            for w in range(3):
                gait = setup.gaits[int(env.gait[w])]
                stay, offers = robot.read(gait, obs[w], float(env.phase[w]), imu[w])
                assert stay == pytest.approx(float(reading.stay[w]), abs=SCORES)
                sector_clear = _clear_of_sector_edges(imu[w])
                if sector_clear and table[gait].get(robot.sector(imu[w])) is None:  # pushed where there is no catch
                    assert reading.offer[w].isnan().all()
                phase_clear = {}
                for dest, (offer, phase) in offers.items():
                    n = setup.gait_index(dest)
                    if not reading.offer[w, n].isnan():
                        assert offer == pytest.approx(float(reading.offer[w, n]), abs=SCORES)
                    phase_clear[dest] = _best_by(guard, reading, env, w, n, ctl.candidates) > 2 * SCORES
                    if phase_clear[dest]:  # the best phase is a choice: the runtimes agree where it is a clear one
                        assert phase == pytest.approx(float(reading.phase[w, n]))
                        choices += 1
                time_s = float(env.episode_length_buf[w]) * env.dt
                decided = robot.decide(gait, obs[w], float(env.phase[w]), time_s, imu[w])
                beats, low = float(best[w] - reading.stay[w]) - guard.margin, float(reading.stay[w]) - estimate.floor
                if sector_clear and abs(beats) > 2 * SCORES and abs(low) > 2 * SCORES:  # decisions away from thresholds
                    assert (decided is not None) == bool(fires[w])
                    decisions += 1
                    if decided is not None and phase_clear[setup.gaits[int(best_gait[w])]]:
                        n = int(best_gait[w])
                        assert decided == (setup.gaits[n], pytest.approx(float(reading.phase[w, n])))
            ctl.step()
    finally:
        sim.close()
    assert fired[:2] == [False, False] and any(fired[2:])  # unarmed, then catches (a margin of 0)
    assert decisions >= 10 and choices >= 10  # of 12 each here: the comparisons above compare


def test_an_estimate_reading_the_critic_is_refused(switching_library, tmp_path):
    setup = load_switching(switching_library)
    with pytest.raises(GaitlibError, match="privileged"):
        export_guard(tmp_path / "guard", policies=[e.policy for e in setup.entries],
                     estimate=_estimate(setup, ("latent", "phase", "value"), margin=0.1), net=setup.resources.net,
                     calibration=setup.resources.calibration)
    assert not (tmp_path / "guard").exists()


def _turned(state, **changes):
    """``state`` (a :class:`~gaitlib.sim.SimState`) with its trunk's quaternion, velocity or rates changed."""
    return dataclasses.replace(state, **{k: v.clone() for k, v in changes.items()})


def test_the_robot_holds_a_catch_skill_until_calm_as_gaitlib_does(switching_library, tmp_path):
    setup = load_switching(switching_library)
    models = {"policies": [e.policy for e in setup.entries], "estimate": _estimate(setup, ("latent", "phase"), 0.1),
              "net": setup.resources.net, "calibration": setup.resources.calibration}
    with pytest.raises(GaitlibError, match="gallop"):
        export_guard(tmp_path / "guard", **models, catchers=("gallop",))
    assert not (tmp_path / "guard").exists()
    robot = _robot_guard(export_guard(tmp_path / "guard", **models, catchers=("stand",)).parent)
    assert robot.spec["catchers"] == ["stand"] and robot.holds_until_calm("stand")
    assert not robot.holds_until_calm("trot")
    assert robot.spec["calm"] == {"tilt_deg": CALM_TILT_DEG, "speed_m_s": CALM_SPEED_M_S,
                                  "rate_rad_s": CALM_RATE_RAD_S, "wait_s": CALM_WAIT_S}
    sim = make_backend("mujoco", num_worlds=2)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        stand = setup.gait_index("stand")
        env.reset_worlds(torch.arange(2), gait=torch.full((2,), stand))
        policy = setup.entries[stand].policy
        with torch.inference_mode():
            for _ in range(15):
                env.step(policy.act(env.get_observations()))
            env.shove(torch.tensor([1]), torch.tensor([[0.0, 300.0, 0.0]]), 3)  # 30 N s sideways: world 1 is shoved
            for _ in range(3):
                env.step(policy.act(env.get_observations()))
        real = env.sim_state
    finally:
        sim.close()

    def rolled(deg: float) -> torch.Tensor:  # the trunk rolled by deg about the world's x axis
        half = math.radians(deg) / 2
        return quat_multiply(torch.tensor([[math.cos(half), math.sin(half), 0.0, 0.0]]).expand(2, 4), real.root_quat)

    fast, turning = real.root_lin_vel.clone(), real.root_ang_vel.clone()
    fast[:, 0] += 1.0
    turning[:, 2] += 1.5
    states = {"as simulated": (real, [True, False]), "rolled 5 deg": (_turned(real, root_quat=rolled(5.0)), None),
              "rolled 20 deg": (_turned(real, root_quat=rolled(20.0)), [False, False]),
              "1 m/s faster": (_turned(real, root_lin_vel=fast), [False, False]),
              "turning 1.5 rad/s faster": (_turned(real, root_ang_vel=turning), [False, False])}
    down = torch.tensor([[0.0, 0.0, -1.0]]).expand(2, 3)
    for name, (state, expected) in states.items():
        gravity = quat_rotate_inverse(state.root_quat, down).numpy()  # the observation's projected gravity
        robot_reads = [robot.calm(gravity[w], state.root_lin_vel[w, :2].numpy(), state.root_ang_vel[w].numpy())
                       for w in range(2)]
        assert robot_reads == is_calm(state).tolist(), name
        if expected is not None:
            assert robot_reads == expected, name
    assert is_calm(states["rolled 5 deg"][0])[0]  # a small lean is still calm
