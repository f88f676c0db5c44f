"""The motion-imitation environment: N A1 worlds, each imitating a gait's reference clip, with rsl-rl's ``VecEnv``
methods (``get_observations``, ``step``; training sees it through :mod:`gaitlib.training.vec_env`).

One control step (30 Hz): the action (N, 12) is a residual around the reference pose one step ahead; with action
noise it becomes the PD targets (clipped to the joint limits), which reach the servos after each world's action
delay (0 or more control steps, randomized); pushes are applied; the backend advances 8 physics
substeps; the phase advances; reward, terminations and time-outs are computed; finished worlds are reset by
reference state initialization (a random phase, the reference's state, freshly randomized dynamics); observations
are built with latency and noise. See :mod:`gaitlib.envs.observations` for the layout.

Beyond rsl-rl's contract the environment exposes what switching needs: :attr:`phase`, :meth:`switch` (make
worlds imitate another gait from a chosen phase, at this moment), :meth:`reset_worlds` and the per-world
reference :attr:`reference`; and what switch-start training needs (:mod:`gaitlib.envs.handover`):
:meth:`handover_states` (what a switch would hand over now) and :meth:`hand_over` (continue from such a state),
which a share of resets use when the environment is given recorded states (:mod:`gaitlib.envs.handing`).

A gait description's ``catch`` task (:attr:`EnvConfig.task`) is trained in the same environment: its clip is a
stance, which the actions are residuals around and the observation shows as a constant reference, and the catch
reward (:mod:`gaitlib.envs.catch`) replaces the imitation reward.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from gaitlib.envs import observations as obs_fn
from gaitlib.envs import rewards as rew_fn
from gaitlib.envs.catch import CATCH_REWARD, CatchStep, CatchTerm, catch_reward, pd_torque
from gaitlib.envs.handing import HandingOver
from gaitlib.envs.handover import HandoverStates
from gaitlib.envs.randomization import (
    PushConfig,
    PushSchedule,
    RandomizationConfig,
    WorldParameters,
    sample_world_parameters,
)
from gaitlib.envs.reference import ReferenceFrame, ReferenceTracker
from gaitlib.envs.rewards import IMITATION_REWARD, RewardTerm
from gaitlib.envs.terminations import TerminationConfig, any_cause, fall_causes
from gaitlib.gaits import ReferenceClip
from gaitlib.rotations import quat_rotate_inverse
from gaitlib.sim import SimBackend, SimState

__all__ = ["EnvConfig", "ImitationEnv"]


@dataclass(frozen=True, kw_only=True)
class EnvConfig:
    """Everything that defines the imitation task apart from the gaits and the backend."""

    episode_seconds: float = 10.0
    """Episode length before a time-out, s."""
    action_scale: float = 0.25
    """PD target = reference joint angles one step ahead + action_scale * action, rad per action unit."""
    action_clip: float = 4.0
    """Actions are clipped to +/- this many units before scaling."""
    reward: tuple[RewardTerm, ...] = IMITATION_REWARD
    """Imitation reward terms, weights and scales."""
    task: str = "imitation"
    """The task of the gait description trained (:data:`gaitlib.gaits.description.TASKS`): ``imitation`` is
    rewarded by :attr:`reward`, ``catch`` by :attr:`catch_reward` (:mod:`gaitlib.envs.catch`)."""
    catch_reward: tuple[CatchTerm, ...] = CATCH_REWARD
    """The catch task's terms and weights, per second."""
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    """Early termination thresholds."""
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    """Domain randomization (paper Table 1)."""
    pushes: PushConfig = field(default_factory=PushConfig)
    """Random trunk pushes (off by default)."""
    random_start_phase: bool = True
    """Reference state initialization at a uniformly random phase (else at phase 0)."""
    observation: obs_fn.ObservationConfig = field(default_factory=obs_fn.ObservationConfig)
    """Options of the actor observation (they must be those the policies were trained with)."""
    contact_penalty: float = 0.0
    """Reward taken off per control step while a non-foot body touches the ground (training with trunk-only
    terminations: :mod:`gaitlib.training.recipe`); 0: none."""
    cycle_sync: bool = False
    """At the start of each gait cycle, move the reference's trunk horizontally to where the robot's is (its heading
    stays): the reward's trunk-position term then measures the drift within one cycle, not since the episode began
    (Peng et al. 2020's code, ``enable_cycle_sync``). The actor observes no horizontal position, so this changes
    the reward only."""


class ImitationEnv(HandingOver):
    """N worlds imitating reference clips on a simulation backend; observations as
    :class:`~gaitlib.envs.observations.ObservationBatch`. The hand-over methods are :class:`~gaitlib.envs.handing.
    HandingOver`'s."""

    def __init__(
        self,
        backend: SimBackend,
        clips: list[ReferenceClip],
        cfg: EnvConfig,
        *,
        seed: int = 0,
        handover: HandoverStates | None = None,
        handover_share: float = 0.0,
    ) -> None:
        """``handover``: recorded states that a share ``handover_share`` of resets start from (switch-start), each
        handed over at a uniformly random phase of the world's gait; ``None``: reference state initialization
        only."""
        if not 0.0 <= handover_share <= 1.0 or (handover_share > 0 and not handover):
            raise ValueError("handover_share must be in [0, 1], and above 0 only with handover states")
        self._handover, self._handover_share = handover, handover_share
        self.backend = backend
        self.cfg = cfg
        self.clips = clips
        self.num_envs = backend.num_worlds
        self.num_actions = backend.robot.num_joints
        self.device = backend.device
        self.dt = backend.control_dt
        self.max_episode_length = round(cfg.episode_seconds / self.dt)
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)
        self.last_episode_length = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)
        """(N,) length in control steps of each world's last finished episode."""

        n, j, dev = self.num_envs, self.num_actions, self.device
        self._gen = torch.Generator().manual_seed(seed)
        self.reference = ReferenceTracker(clips, n, dev)
        self._pushes = PushSchedule(cfg.pushes, n, self.dt, self._gen)
        self._lower = torch.tensor(backend.robot.joint_lower, device=dev)
        self._upper = torch.tensor(backend.robot.joint_upper, device=dev)
        self._action = torch.zeros(n, j, device=dev)  # last action taken (after clipping), action units
        delays = cfg.randomization.action_delay_steps[1] + 1 if cfg.randomization.enabled else 1
        self._targets = torch.zeros(n, delays, j, device=dev)  # PD targets of the last steps, newest first, rad
        self._history = torch.zeros(n, obs_fn.HISTORY, obs_fn.FRAME_DIM, device=dev)  # observed frames
        self._last_reading = torch.zeros(n, obs_fn.FRAME_DIM, device=dev)  # clean frame of the previous step
        self._params = sample_world_parameters(cfg.randomization, n, self._gen)
        self._dynamics = torch.zeros(n, obs_fn.width(obs_fn.DYNAMICS), device=dev)  # what the critic sees
        self._state: SimState = backend.state()
        self.trunk_acceleration = torch.zeros(n, 3, device=dev)
        """(N, 3) the trunk's mean acceleration over the last control step, trunk frame, m/s^2, gravity left out:
        what an IMU's accelerometer reads at the control rate once the attitude's gravity is taken away (0 just
        after a reset). Read by the guard's survival estimate (its ``imu`` input), not by the policies."""
        self._terms = {t.name: torch.zeros(n, device=dev) for t in self._reward_terms}
        self._obs: obs_fn.ObservationBatch | None = None
        self.reset_worlds(torch.arange(n, device=dev))

    # ------------------------------------------------------------------------------------ rsl-rl's methods
    def get_observations(self) -> obs_fn.ObservationBatch:
        assert self._obs is not None
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[obs_fn.ObservationBatch, torch.Tensor, torch.Tensor, dict]:
        cfg = self.cfg
        actions = actions.to(self.device).clamp(-cfg.action_clip, cfg.action_clip)
        last_action, self._action = self._action, actions
        noise = self._noise(actions.shape, cfg.randomization.action_noise)
        targets = self.reference.joint_pos(self.dt) + cfg.action_scale * actions + noise
        clipped = torch.maximum(torch.minimum(targets, self._upper), self._lower)
        self._targets = torch.cat([clipped.unsqueeze(1), self._targets[:, :-1]], dim=1)
        delay = self._params.action_delay.to(self.device).long()
        applied = self._targets[torch.arange(self.num_envs, device=self.device), delay]
        self.backend.set_pd_targets(applied)

        changed = self._pushes.advance()
        if len(changed):
            self.backend.set_trunk_force(changed, self._pushes.force[changed].to(self.device))
        before = self._state.root_lin_vel.clone()
        diverged = self.backend.step().to(self.device)
        cycle_started = self.reference.advance(self.dt)
        self.episode_length_buf += 1
        self._state = state = self.backend.state()
        self.trunk_acceleration = quat_rotate_inverse(state.root_quat, (state.root_lin_vel - before) / self.dt)
        if cfg.cycle_sync and bool(cycle_started.any()):
            synced = cycle_started.nonzero().squeeze(1)
            self.reference.sync_position(synced, state.root_pos[synced])

        observed = self._observed_frames(self.reference)  # now, then the goals: the reward reads now
        ref = observed[0]
        causes = fall_causes(state.body_contact, state.trunk_contact, state.root_pos[:, 2], state.root_quat,
                             ref.root_quat, cfg.termination)
        terminated = diverged | any_cause(causes)
        if cfg.task == "catch":
            p, limit = self._params, self.backend.robot.torque_limit
            torque = pd_torque(applied, state.joint_pos, state.joint_vel, p.kp.to(self.device), p.kd.to(self.device),
                               limit=limit)
            step = CatchStep(state=state, ref=ref, action=actions, last_action=last_action, torque=torque,
                             terminated=terminated)
            reward, self._terms = catch_reward(cfg.catch_reward, step, dt=self.dt)
        else:
            reward, self._terms = rew_fn.reward(cfg.reward, state, ref)
        if cfg.contact_penalty:
            reward = reward - cfg.contact_penalty * state.body_contact.float()
        time_out = (self.episode_length_buf >= self.max_episode_length) & ~terminated
        dones = terminated | time_out

        extras = {
            "time_outs": time_out,
            "fall_causes": causes | {"diverged": diverged},
            "touch": state.body_contact,  # a non-foot body on the ground this step, whatever ends the episode
            "log": {f"/reward/{name}": value.mean() for name, value in self._terms.items()}
            | {"/termination/rate": terminated.float().mean(), "/termination/diverged": diverged.float().mean(),
               "/termination/touch": state.body_contact.float().mean()},
        }
        done_ids = dones.nonzero().squeeze(1)
        self._record_frame()
        if len(done_ids):
            self.last_episode_length[done_ids] = self.episode_length_buf[done_ids]
            self.reset_worlds(done_ids)  # rebuilds the observations
        else:
            self._obs = self._observations(observed=observed)
        return self._obs, reward, dones, extras

    # ------------------------------------------------------------------------------------------ switching
    @property
    def phase(self) -> torch.Tensor:
        """(N,) the phase in [0, 1) of each world's reference."""
        return self.reference.wrapped_phase

    @property
    def gait(self) -> torch.Tensor:
        """(N,) index into ``clips`` of the gait each world imitates."""
        return self.reference.gait

    @property
    def sim_state(self) -> SimState:
        """The backend's readings after the last step."""
        return self._state

    @property
    def world_parameters(self) -> WorldParameters:
        """The randomized parameters of every world since its last reset."""
        return self._params

    def switch(self, world_ids: torch.Tensor, gait: torch.Tensor, phase: torch.Tensor) -> None:
        """From now on, worlds ``world_ids`` imitate ``gait`` (k,) starting at ``phase`` (k,) in [0, 1), with the
        reference re-anchored where each robot stands and faces. Observations are rebuilt for the new reference."""
        s = self._state
        self.reference.start(world_ids, gait, phase, s.root_pos[world_ids], s.root_quat[world_ids])
        self._obs = self._observations()

    def preview_switch(
        self, world_ids: torch.Tensor, gait: torch.Tensor, phases: torch.Tensor
    ) -> obs_fn.ObservationBatch:
        """The observations worlds ``world_ids`` (k,) would have right after ``switch`` to ``gait`` (k,) at each of
        the candidate ``phases`` (C,), as k * C rows (world-major); nothing changes in the environment."""
        k, c = len(world_ids), len(phases)
        rows = world_ids.repeat_interleave(c)
        preview = ReferenceTracker(self.clips, k * c, self.device)
        s = self._state
        preview.start(
            torch.arange(k * c, device=self.device),
            gait.repeat_interleave(c),
            phases.to(self.device).repeat(k),
            s.root_pos[rows],
            s.root_quat[rows],
        )
        return self._observations(preview, rows)

    def set_push_max(self, force: float) -> None:
        """Draw the magnitudes of pushes that start from now on up to ``force``, N (a training curriculum)."""
        self._pushes.set_max_force(force)

    @property
    def push_force(self) -> torch.Tensor:
        """(N, 3) the push force currently applied to each trunk, world frame, N."""
        return self._pushes.force.to(self.device)

    def enable_pushes(self, world_ids: torch.Tensor, enabled: bool) -> None:
        """Let random pushes hit worlds ``world_ids`` (the first after a fresh quiet time), or start no new push on
        them (a push under way runs out). Worlds start enabled; a reset keeps the setting."""
        ids = world_ids.cpu()
        self._pushes.enable(ids, enabled)
        self.backend.set_trunk_force(world_ids, self._pushes.force[ids].to(self.device))

    def reset_worlds(self, world_ids: torch.Tensor, *, gait: torch.Tensor | None = None) -> None:
        """Reference state initialization of ``world_ids``: new dynamics, a random (or zero) phase, the reference's
        state at that phase, a clean history. ``gait`` (k,) picks their gaits (default: keep the current one)."""
        k = len(world_ids)
        if gait is not None:
            self.reference.gait[world_ids] = gait
        gait_ids = self.reference.gait[world_ids]
        if self.cfg.random_start_phase:
            phase = torch.rand(k, generator=self._gen).to(self.device)
        else:
            phase = torch.zeros(k, device=self.device)
        identity = torch.zeros(k, 4, device=self.device)
        identity[:, 0] = 1.0
        self.reference.start(world_ids, gait_ids, phase, torch.zeros(k, 3, device=self.device), identity)
        ref = self.reference.frame(world_ids=world_ids)
        self._randomize(world_ids)
        self.backend.reset(world_ids, ref)
        self._targets[world_ids] = ref.joint_pos.unsqueeze(1)  # a delayed action's servo holds the start pose
        self._pushes.reset(world_ids.cpu())
        self.episode_length_buf[world_ids] = 0
        self._action[world_ids] = 0.0
        self.trunk_acceleration[world_ids] = 0.0
        self._state = self.backend.state()
        reading = self._clean_frame()[world_ids]
        self._last_reading[world_ids] = reading
        self._history[world_ids] = reading.unsqueeze(1).expand(-1, obs_fn.HISTORY, -1)
        if self._handover_share > 0:
            chosen = world_ids[(torch.rand(k, generator=self._gen) < self._handover_share).to(self.device)]
            if len(chosen):
                rows = torch.randint(len(self._handover), (len(chosen),), generator=self._gen).numpy()
                self.hand_over(chosen, self._handover.select(rows), torch.rand(len(chosen), generator=self._gen))
                return
        self._obs = self._observations()

    # ------------------------------------------------------------------------------------------ internals
    @property
    def _reward_terms(self) -> tuple:
        return self.cfg.catch_reward if self.cfg.task == "catch" else self.cfg.reward

    def _randomize(self, world_ids: torch.Tensor) -> None:
        k = len(world_ids)
        params = sample_world_parameters(self.cfg.randomization, k, self._gen)
        ids = world_ids.cpu()
        for name in params.__dataclass_fields__:
            getattr(self._params, name)[ids] = getattr(params, name)
        self.backend.set_dynamics(
            world_ids,
            gravity_scale=params.gravity_scale.to(self.device),
            mass_scale=params.mass_scale.to(self.device),
            friction=params.friction.to(self.device),
        )
        kp = params.kp.to(self.device).unsqueeze(1).expand(k, self.num_actions)
        kd = params.kd.to(self.device).unsqueeze(1).expand(k, self.num_actions)
        self.backend.set_pd_gains(world_ids, kp, kd)
        self._dynamics[world_ids] = torch.stack([getattr(params, f.name) for f in obs_fn.DYNAMICS], 1).to(self.device)

    def _noise(self, shape: torch.Size, amplitude: float) -> torch.Tensor:
        if not self.cfg.randomization.enabled or amplitude == 0.0:
            return torch.zeros(shape, device=self.device)
        return (amplitude * (2 * torch.rand(shape, generator=self._gen) - 1)).to(self.device)

    def _clean_frame(self) -> torch.Tensor:
        s = self._state
        return obs_fn.proprioceptive_frame(s.joint_pos, s.root_quat, s.root_ang_vel, s.foot_contact, self._action)

    def _record_frame(self) -> None:
        """Push the newest observed frame (latency-interpolated, noisy) into the history."""
        reading = self._clean_frame()
        lag = (self._params.latency.to(self.device) / self.dt).unsqueeze(1)
        observed = reading + lag * (self._last_reading - reading)
        sensed = obs_fn.SENSED  # actions are known exactly
        observed[:, sensed] += self._noise(observed[:, sensed].shape, self.cfg.randomization.observation_noise)
        self._last_reading = reading
        self._history = torch.cat([observed.unsqueeze(1), self._history[:, :-1]], dim=1)

    def _observed_frames(self, reference: ReferenceTracker) -> list[ReferenceFrame]:
        """The references an observation reads: now, then at each of the goal offsets (one read of the clips)."""
        return reference.frames([0.0, *(k * self.dt for k in obs_fn.REFERENCE_OFFSETS)])

    def _observations(
        self,
        reference: ReferenceTracker | None = None,
        rows: torch.Tensor | None = None,
        observed: Sequence[ReferenceFrame] | None = None,
    ) -> obs_fn.ObservationBatch:
        """Observations of every world under its reference, or of the worlds ``rows`` (R,) under ``reference`` (a
        tracker of R rows); ``observed``: the :meth:`_observed_frames` of every world, when already read."""
        reference = reference or self.reference
        ids = slice(None) if rows is None else rows
        now, *frames = observed or self._observed_frames(reference)
        s = self._state
        parts = [self._history[ids].flatten(1), obs_fn.reference_features(frames)]
        if self.cfg.observation.heading:
            parts.append(obs_fn.heading_error(s.root_quat[ids], now.root_quat))
        actor = torch.cat(parts, dim=-1)
        privileged = obs_fn.privileged_features(
            s.root_quat[ids],
            s.root_lin_vel[ids],
            s.root_pos[ids, 2],
            reference.wrapped_phase,
            self._dynamics[ids],
            self.push_force[ids],
            self._params.action_delay.to(self.device)[ids] if self.cfg.observation.critic_delay else None,
        )
        return obs_fn.ObservationBatch(policy=actor, privileged=privileged)
