"""The backend contract on both real simulators: standing, pushes, per-world randomization, resets, divergence."""

from __future__ import annotations

import math

import pytest
import torch

from gaitlib.robots import get_robot
from gaitlib.robots.a1 import constants as a1
from gaitlib.sim import KinematicState, make_backend, standing_state

ROBOT = get_robot("a1")


def hold(backend, steps: int) -> torch.Tensor:
    """Hold the default pose for ``steps`` control steps; return which worlds ever diverged."""
    targets = torch.tensor(a1.DEFAULT_JOINT_POS).repeat(backend.num_worlds, 1)
    backend.set_pd_targets(targets)
    diverged = torch.zeros(backend.num_worlds, dtype=torch.bool)
    for _ in range(steps):
        diverged |= backend.step()
    return diverged


def airborne(num: int, height: float = 1.5) -> KinematicState:
    state = standing_state(ROBOT, num)
    state.root_pos[:, 2] = height
    return state


def test_state_shapes_and_dtypes(make) -> None:
    backend = make(3)
    s = backend.state()
    assert s.root_pos.shape == (3, 3) and s.root_quat.shape == (3, 4)
    assert s.root_lin_vel.shape == (3, 3) and s.root_ang_vel.shape == (3, 3)
    assert s.joint_pos.shape == (3, 12) and s.joint_vel.shape == (3, 12)
    assert s.foot_contact.shape == (3, 4) and s.foot_contact.dtype == torch.bool
    assert s.foot_pos.shape == (3, 4, 3) and s.body_contact.shape == (3,)
    assert s.trunk_contact.shape == (3,) and s.trunk_contact.dtype == torch.bool
    assert s.root_pos.dtype == torch.float32
    assert backend.control_dt == pytest.approx(1 / 30) and backend.substeps == 8


def test_stands_five_seconds_under_pd_hold(make) -> None:
    backend = make(2)
    diverged = hold(backend, steps=150)
    s = backend.state()
    assert not diverged.any()
    # PD sag at kp 60 lowers the trunk a little below the kinematic standing height (0.2686 m).
    assert torch.all((s.root_pos[:, 2] > 0.23) & (s.root_pos[:, 2] < a1.STANDING_HEIGHT))
    assert torch.all(s.root_quat[:, 0].abs() > 0.999)  # upright
    assert torch.all(s.root_pos[:, :2].norm(dim=1) < 0.05)  # no drift
    assert s.foot_contact.all() and not s.body_contact.any() and not s.trunk_contact.any()
    assert torch.all(s.foot_pos[..., 2] < a1.FOOT_RADIUS + 0.005)
    assert torch.all((s.joint_pos - torch.tensor(a1.DEFAULT_JOINT_POS)).abs() < 0.15)


def test_the_trunk_on_the_ground_is_told_apart_from_a_leg_on_it(make) -> None:
    """A robot lying on its back touches the ground with its trunk (a fall by any definition); one lowered onto
    folded legs, its trunk held up by its thighs and calves, touches it with its legs only; a standing one with its
    feet only."""
    backend = make(3)
    state = standing_state(ROBOT, 3)
    state.root_quat[1] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # upside down
    state.root_pos[1, 2] = 0.08
    state.joint_pos[2] = torch.tensor([0.0, 0.0, -2.7] * 4)  # thighs down, calves folded up: on its knees
    state.root_pos[2, 2] = 0.3
    backend.reset(torch.arange(3), state)
    backend.set_pd_targets(state.joint_pos)
    for _ in range(15):
        assert not backend.step().any()
    s = backend.state()
    assert s.trunk_contact.tolist() == [False, True, False]
    assert s.body_contact.tolist() == [False, True, True]
    assert s.root_pos[2, 2] > 0.18 and not s.foot_contact[2].any()  # up on its knees, no foot down


def test_trunk_push_changes_velocity_by_impulse_over_mass(make) -> None:
    """In the air (no ground forces), a push of F for dt changes the trunk velocity by F dt / m."""
    backend = make(2)
    backend.reset(torch.arange(2), airborne(2))
    force, duration = 50.0, 0.2
    steps = round(duration / backend.control_dt)
    v0 = backend.state().root_lin_vel.clone()
    backend.set_trunk_force(torch.tensor([0]), torch.tensor([[0.0, force, 0.0]]))
    for _ in range(steps):
        backend.step()
    dv = backend.state().root_lin_vel - v0
    expected = force * steps * backend.control_dt / a1.TOTAL_MASS
    assert dv[0, 1].item() == pytest.approx(expected, rel=0.05)
    assert abs(dv[1, 1].item()) < 1e-3  # the other world is not pushed
    # Both fall freely: dz = -g t.
    assert dv[:, 2].numpy() == pytest.approx([-9.81 * steps * backend.control_dt] * 2, rel=0.02)


def test_low_friction_world_slides_further(make) -> None:
    backend = make(2)
    ids = torch.arange(2)
    backend.set_dynamics(
        ids, gravity_scale=torch.ones(2), mass_scale=torch.ones(2), friction=torch.tensor([0.25, 1.5])
    )
    hold(backend, steps=15)
    start = backend.state().root_pos[:, :2].clone()
    backend.set_trunk_force(ids, torch.tensor([[60.0, 0.0, 0.0], [60.0, 0.0, 0.0]]))
    hold(backend, steps=15)
    backend.set_trunk_force(ids, torch.zeros(2, 3))
    hold(backend, steps=15)
    slide = backend.state().root_pos[:, 0] - start[:, 0]
    assert slide[0] > slide[1] + 0.05


def test_heavier_gravity_or_softer_gains_lower_the_standing_height_after_many_steps(make) -> None:
    # Changed after 30 steps: the newton backend replays a captured graph from its second step on, and a change made
    # later must still reach it.
    backend = make(3)
    ids = torch.arange(3)
    hold(backend, steps=30)
    backend.set_dynamics(
        ids, gravity_scale=torch.tensor([0.8, 1.2, 1.0]), mass_scale=torch.ones(3), friction=torch.full((3,), 0.8)
    )
    backend.set_pd_gains(ids[2:], kp=torch.full((1, ROBOT.num_joints), 5.0), kd=torch.full((1, ROBOT.num_joints), 0.5))
    hold(backend, steps=60)
    z = backend.state().root_pos[:, 2]
    assert z[1] < z[0] - 0.002  # heavier
    assert z[2] < z[0] - 0.05  # too soft to stand


def test_heavier_robot_falls_the_same_but_pushes_move_it_less(make) -> None:
    backend = make(2)
    ids = torch.arange(2)
    backend.set_dynamics(
        ids, gravity_scale=torch.ones(2), mass_scale=torch.tensor([1.0, 1.15]), friction=torch.full((2,), 0.8)
    )
    backend.reset(ids, airborne(2))
    backend.set_trunk_force(ids, torch.tensor([[0.0, 50.0, 0.0], [0.0, 50.0, 0.0]]))
    for _ in range(6):
        backend.step()
    v = backend.state().root_lin_vel
    assert v[1, 1] / v[0, 1] == pytest.approx(1 / 1.15, rel=0.03)
    assert v[0, 2].item() == pytest.approx(v[1, 2].item(), rel=0.01)


def test_randomizing_one_world_leaves_the_others_untouched(backend_name: str) -> None:
    plain = make_backend(backend_name, num_worlds=2, device="cpu")
    varied = make_backend(backend_name, num_worlds=2, device="cpu")
    one = torch.tensor([0])
    varied.set_dynamics(one, gravity_scale=torch.tensor([1.2]), mass_scale=torch.tensor([0.85]),
                        friction=torch.tensor([0.25]))
    varied.set_pd_gains(one, torch.full((1, 12), 45.0), torch.full((1, 12), 0.9))
    hold(plain, 30)
    hold(varied, 30)
    a, b = plain.state(), varied.state()
    assert torch.equal(a.joint_pos[1], b.joint_pos[1]) and torch.equal(a.root_pos[1], b.root_pos[1])
    assert not torch.allclose(a.root_pos[0], b.root_pos[0])
    plain.close()
    varied.close()


def test_reset_leaves_other_worlds_bit_identical(backend_name: str) -> None:
    a = make_backend(backend_name, num_worlds=3, device="cpu")
    b = make_backend(backend_name, num_worlds=3, device="cpu")
    targets = torch.tensor(a1.DEFAULT_JOINT_POS).repeat(3, 1)
    targets[:, 1::3] += 0.3  # lean the thighs: a motion, not a rest
    for backend in (a, b):
        backend.set_pd_targets(targets)
    for step in range(20):
        if step == 10:
            start = airborne(1, height=0.5)
            b.reset(torch.tensor([1]), start)
            b.set_pd_targets(targets)
        a.step()
        b.step()
    sa, sb = a.state(), b.state()
    for world in (0, 2):
        assert torch.equal(sa.root_pos[world], sb.root_pos[world])
        assert torch.equal(sa.joint_vel[world], sb.joint_vel[world])
    assert not torch.equal(sa.root_pos[1], sb.root_pos[1])
    a.close()
    b.close()


def test_reset_puts_the_world_in_the_given_state(make) -> None:
    backend = make(2)
    state = airborne(1, height=0.8)
    state.root_quat[0] = torch.tensor([math.cos(0.2), 0.0, 0.0, math.sin(0.2)])  # yaw 0.4 rad
    state.root_lin_vel[0] = torch.tensor([0.5, -0.2, 0.1])
    state.root_ang_vel[0] = torch.tensor([0.0, 0.0, 0.3])
    state.joint_pos[0, 2] = -1.5
    backend.reset(torch.tensor([1]), state)
    s = backend.state()
    for name in ("root_pos", "root_quat", "root_lin_vel", "root_ang_vel", "joint_pos", "joint_vel"):
        assert torch.allclose(getattr(s, name)[1], getattr(state, name)[0], atol=1e-5), name


def test_diverging_world_is_reported_and_reset(make) -> None:
    backend = make(3)
    hold(backend, 5)
    before = backend.state()
    backend.set_trunk_force(torch.tensor([1]), torch.tensor([[1e12, 0.0, 1e12]]))
    diverged = backend.step()
    assert diverged.tolist() == [False, True, False]
    s = backend.state()
    for name in ("root_pos", "root_lin_vel", "joint_pos", "joint_vel"):
        assert torch.isfinite(getattr(s, name)).all()
    # World 1 is back in its last reset state: the standing state it was created in.
    start = standing_state(ROBOT, 1)
    assert torch.allclose(s.root_pos[1], start.root_pos[0], atol=1e-5)
    assert torch.allclose(s.joint_pos[1], start.joint_pos[0], atol=1e-5)
    assert torch.allclose(s.root_pos[0], before.root_pos[0], atol=0.01)
    assert not backend.step()[1]  # the force was cleared with the reset


def test_set_dynamics_keeps_the_world_where_it_is(make) -> None:
    backend = make(2)
    hold(backend, 10)
    before = backend.state()
    ids = torch.arange(2)
    backend.set_dynamics(ids, gravity_scale=torch.ones(2), mass_scale=torch.full((2,), 1.1), friction=torch.ones(2))
    backend.set_pd_gains(ids, torch.full((2, 12), 70.0), torch.full((2, 12), 1.0))
    backend.step()
    after = backend.state()
    assert torch.allclose(after.root_pos, before.root_pos, atol=0.01)
    assert torch.allclose(after.joint_pos, before.joint_pos, atol=0.05)


def test_feet_stay_on_top_of_the_ground_whatever_the_friction(make) -> None:
    """Pyramidal friction cones soften the normal contact as friction grows; the model's impratio keeps the feet
    from sinking at the high end of the randomized friction range (paper Table 1: 0.25-1.5)."""
    backend = make(2)
    ids = torch.arange(2)
    backend.set_dynamics(ids, gravity_scale=torch.full((2,), 1.2), mass_scale=torch.full((2,), 1.15),
                         friction=torch.tensor([0.25, 1.5]))
    hold(backend, 60)
    s = backend.state()
    assert torch.all(s.foot_pos[..., 2] > a1.FOOT_RADIUS - 0.004)  # sunk at most 4 mm
    assert (s.root_pos[0, 2] - s.root_pos[1, 2]).abs() < 0.003
    assert not s.body_contact.any()


def test_closing_drops_the_worlds_even_while_the_backend_is_still_referred_to(make) -> None:
    """close() lets the worlds go itself, whatever still refers to the backend (an environment in a reference
    cycle keeps it until Python's collector runs): only what names the backend stays; a second close is
    harmless."""
    sim = make(2)
    sim.step()
    sim.close()
    assert set(vars(sim)) == {"robot", "num_worlds", "device"}
    sim.close()
