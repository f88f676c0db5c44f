"""The meta-controller (paper Algorithm 1) on the real simulator with a tiny library."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import DISTURBANCE_LEAD_S, RandomizationConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta import MetaController, load_switching
from gaitlib.meta.episode import run_episode
from gaitlib.sim import make_backend
from gaitlib.strategies.net import NetStrategy
from gaitlib.strategies.value import ValueStrategy


class Tagged(torch.nn.Module):
    """A library policy whose actions are all ``tag`` (its latent and value are the real policy's)."""

    def __init__(self, policy, tag: float) -> None:
        super().__init__()
        self.policy, self.tag = policy, tag

    def act(self, obs):
        return torch.full((len(obs), 12), self.tag)

    def latent(self, obs):
        return self.policy.latent(obs)

    def value(self, obs):
        return self.policy.value(obs)


@pytest.fixture
def setup(switching_library):
    return load_switching(switching_library)


def make_env(setup, worlds: int = 4, backend: str = "mujoco"):
    sim = make_backend(backend, num_worlds=worlds)
    cfg = EnvConfig(episode_seconds=100.0, randomization=RandomizationConfig(enabled=False))
    return sim, setup.make_env(sim, cfg, seed=1)


def test_actions_come_from_the_active_policy_only(setup) -> None:
    sim, env = make_env(setup)
    try:
        policies = [Tagged(e.policy, tag=0.1 * (g + 1)) for g, e in enumerate(setup.entries)]
        stand, trot = setup.gait_index("stand"), setup.gait_index("trot")
        env.reset_worlds(torch.arange(4), gait=torch.tensor([trot, trot, stand, stand]))
        ctl = MetaController(env, policies, ValueStrategy(threshold=-math.inf), typical_value=torch.ones(2))
        ctl.request(torch.tensor([0]), stand)  # switches at once (threshold -inf)
        for step in range(6):
            before = env.gait.clone()
            result = ctl.step()
            switched = {e.world for e in result.events}
            assert switched == ({0} if step == 0 else set())
            expected = 0.1 * (before + 1)
            expected[0] = 0.1 * (stand + 1)  # world 0 acts with its new policy from the switch on
            assert torch.allclose(result.actions, expected.unsqueeze(1).expand(4, 12))
        assert env.gait.tolist() == [stand, trot, stand, stand]
    finally:
        sim.close()


def test_a_request_the_strategy_never_takes_is_forced_at_the_deadline(setup) -> None:
    sim, env = make_env(setup, worlds=2)
    try:
        net = setup.resources.net
        policies = [e.policy for e in setup.entries]
        ctl = MetaController(env, policies, NetStrategy(net, threshold=1.01), deadline_s=0.5)  # never reached
        trot, stand = setup.gait_index("trot"), setup.gait_index("stand")
        env.reset_worlds(torch.arange(2), gait=torch.tensor([trot, trot]))
        ctl.request(torch.tensor([1]), stand)
        events = []
        for _ in range(ctl.deadline_steps + 3):
            result = ctl.step()
            assert torch.isnan(result.best_score[0])  # world 0 waits for nothing
            if result.waiting[1]:
                assert 0.0 <= result.best_score[1] <= 1.0 and 0.0 <= result.best_phase[1] < 1.0
            events += result.events
        assert len(events) == 1
        event = events[0]
        assert event.world == 1 and event.forced and event.source == trot and event.dest == stand
        assert event.step == ctl.deadline_steps == 15 and event.wait_s == pytest.approx(0.5)
        assert env.gait[1] == stand and env.phase[1] >= 0
    finally:
        sim.close()


def test_value_strategies_see_the_destination_critic_on_every_candidate(setup) -> None:
    sim, env = make_env(setup, worlds=2)
    try:
        ctl = setup.controller(env, "tmt-value")
        seen = []
        decide = ctl.strategy.decide
        ctl.strategy.decide = lambda query: seen.append(query) or decide(query)
        ctl.request(torch.tensor([0, 1]), 1 - env.gait)
        ctl.step()
        query = seen[0]
        assert query.dest_value.shape == (2, 16) and torch.isfinite(query.dest_value).all()
        assert query.dest_value.std() > 0  # the candidates differ
        assert query.latent.shape == (2, 16)
    finally:
        sim.close()


@pytest.fixture(scope="module")
def shipped():
    """The shipped library: trained policies, so a trot runs the whole request window without falling."""
    return load_switching(None)


@pytest.mark.parametrize("strategy", ["random", "value", "tmt", "tmt-value", "net"])
def test_run_episode_records_the_switch(shipped, strategy) -> None:
    request_s, deadline_s = 0.3, 0.5
    trace = run_episode(
        shipped, source="trot", dests=["stand"], strategy=strategy, request_s=request_s, hold_s=0.9,
        deadline_s=deadline_s, seed=2, backend="mujoco",
    )
    trot, stand = shipped.gait_index("trot"), shipped.gait_index("stand")
    steps, (event,), (switch_s,) = len(trace.time_s), trace.switches, trace.switches_s
    assert trace.qpos.shape == (steps, 19) and trace.foot_contact.shape == (steps, 4)
    assert (event.source, event.dest) == (trot, stand) and 0.0 <= event.phase < 1.0
    assert trace.requests_s == [pytest.approx(round(request_s / trace.dt) * trace.dt)]
    assert request_s - 1e-9 <= switch_s <= request_s + deadline_s + 1e-9
    assert event.wait_s == pytest.approx(switch_s - trace.requests_s[0])
    assert (trace.active[: event.step] == trot).all() and (trace.active[event.step :] == stand).all()
    waiting = np.isfinite(trace.score)  # the best score is recorded exactly while the request waits
    assert waiting.sum() == (0 if strategy == "random" else event.step - round(request_s / trace.dt) + 1)
    if strategy == "random":
        assert event.wait_s == 0.0 and math.isnan(event.score) and not event.forced
    elif event.forced:
        assert event.wait_s == pytest.approx(deadline_s, abs=trace.dt)


def test_pushes_hit_only_inside_the_disturbance_window() -> None:
    request_s, deadline_s = 1.0, 0.5
    trace = run_episode(
        load_switching(None),  # trained policies: the robot outlives the window (pace to stand: 99% at 0 N)
        source="pace",
        dests=["stand"],
        strategy="net",
        request_s=request_s,
        push_n=40.0,
        hold_s=2.5,  # a push would start again within 1 s of the window's end (the longest quiet time)
        deadline_s=deadline_s,
        seed=3,
    )
    assert trace.stayed_up and trace.time_s[-1] > request_s + deadline_s + 0.5
    pushed = trace.time_s[trace.push > 0]
    assert len(pushed) and set(np.round(trace.push[trace.push > 0], 3)) == {40.0}  # fixed magnitude
    longest_push = 0.3
    assert pushed.min() > request_s - DISTURBANCE_LEAD_S
    assert pushed.max() <= request_s + deadline_s + longest_push + trace.dt  # the last push runs out


def test_a_sequence_chains_its_switches_each_in_its_own_push_window(shipped) -> None:
    request_s, hold_s, deadline_s, lead_s = 0.9, 1.4, 0.5, DISTURBANCE_LEAD_S
    trace = run_episode(
        shipped, source="pace", dests=["stand", "pace"], strategy="tmt", request_s=request_s, hold_s=hold_s,
        push_n=20.0, deadline_s=deadline_s, seed=4, backend="mujoco",
    )
    pace, stand = shipped.gait_index("pace"), shipped.gait_index("stand")
    assert trace.stayed_up and [(e.source, e.dest) for e in trace.switches] == [(pace, stand), (stand, pace)]
    dt, (first, second) = trace.dt, trace.switches_s
    assert trace.requests_s[0] == pytest.approx(round(request_s / dt) * dt)
    assert trace.requests_s[1] == pytest.approx(first + hold_s, abs=dt + 1e-9)  # the hold counts from the switch
    assert trace.time_s[-1] == pytest.approx(second + hold_s, abs=dt + 1e-9)
    for event, request in zip(trace.switches, trace.requests_s, strict=True):
        assert event.wait_s == pytest.approx(event.step * dt - request) and event.wait_s <= deadline_s + 1e-9
    active = trace.active
    assert (active[trace.time_s <= first] == pace).all() and (active[trace.time_s > second] == pace).all()
    assert (active[(trace.time_s > first) & (trace.time_s <= second)] == stand).all()
    pushed = trace.time_s[trace.push > 0]
    for request in trace.requests_s:  # every request meets pushes, from the lead before it to the deadline after
        assert ((pushed > request - lead_s) & (pushed <= request + deadline_s + 0.3 + dt)).any()
    inside = [(pushed > r - lead_s) & (pushed <= r + deadline_s + 0.3 + dt) for r in trace.requests_s]
    assert (inside[0] | inside[1]).all()  # and nowhere else


def test_a_sequence_that_repeats_the_running_gait_is_refused(shipped) -> None:
    with pytest.raises(GaitlibError, match=r"'stand' is requested while the robot already runs it"):
        run_episode(shipped, source="trot", dests=["stand", "stand"], backend="mujoco")
    with pytest.raises(GaitlibError, match=r"the hold \(0.5 s\) longer than the pushes' lead before a request"):
        run_episode(shipped, source="trot", dests=["stand"], request_s=1.0, hold_s=0.5, backend="mujoco")


@pytest.mark.newton
def test_the_meta_controller_runs_on_newton(setup) -> None:
    sim, env = make_env(setup, worlds=2, backend="newton")
    try:
        ctl = setup.controller(env, "net", deadline_s=0.2)
        ctl.request(torch.tensor([0, 1]), 1 - env.gait)
        events = []
        for _ in range(8):
            events += ctl.step().events
        assert {e.world for e in events} == {0, 1}
    finally:
        sim.close()
