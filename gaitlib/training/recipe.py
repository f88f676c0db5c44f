"""The training recipe's robustness levers, one place: how a gait is pushed, what ends its episodes, what its leg
touches cost, its discount and its action delay. The defaults are the shipped library's recipe (the robust recipe the
ablation in docs/ablation.md chose); :data:`PAPER_RECIPE` is the one of the libraries before it. Each lever is an
option of ``gaitlib train`` and is recorded in the entry's metadata (``training.recipe``).

The field's practice each lever follows:

- pushes as velocity kicks: legged_gym sets the base's horizontal velocity to a random value of up to 1 m/s along
  each axis every 15 s (``push_robots``, ``max_push_vel_xy = 1.``, github.com/leggedrobotics/legged_gym
  ``legged_robot_config.py``); Isaac Lab's ``push_by_setting_velocity`` adds a velocity drawn per axis, mjlab up to
  0.5 m/s every 1-3 s. Here a kick's change of speed is drawn the same way, per axis (its magnitude up to
  sqrt(2) ``kick_max``; ``--kick-draw disk`` draws a random direction and a magnitude of up to ``kick_max``). A kick
  is a horizontal force held for one control step whose impulse gives the nominal A1
  (:data:`~gaitlib.robots.a1.constants.TOTAL_MASS`) the drawn change of speed; a world whose mass is randomized
  heavier or lighter changes speed by that much less or more.
- terminations on the trunk only (legged_gym's ``terminate_after_contacts_on = ["base"]``), a leg's touch then
  penalized per control step (legged_gym's ``penalize_contacts_on = ["thigh", "calf"]``, ``collision`` scale -1).
- the discount: rsl-rl's locomotion tasks use 0.99 (lambda 0.95) against the paper's 0.95 (lambda 0.95), a horizon
  of about 0.7 s at 30 Hz, shorter than a fall takes to unfold.
- the action delay: trained at a fixed number of control steps instead of Table 1's random 0-1, or known to the
  critic (privileged, as mjlab's motion-tracking task gives its critic state the actor lacks).
- the imitation reward's tolerance after a shove: the reference re-anchored horizontally where the robot is at the
  start of every gait cycle, as Peng et al. 2020's code does by default (``ImitationTask(enable_cycle_sync=True)``,
  github.com/google-research/motion_imitation). Without it the trunk-position term compares against a track
  anchored where the episode began, so a shove's displacement costs reward for the rest of the episode, though
  neither the actor nor the critic observes a horizontal position.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from gaitlib.defaults import Falls
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import PUSH_DRAWS, PushConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.robots.a1.constants import TOTAL_MASS
from gaitlib.training.presets import TrainPreset

__all__ = ["PAPER_RECIPE", "PUSH_KINDS", "Recipe"]

_KICK_DRAW_BEFORE_ITS_OPTION = "disk"  # entries recorded before kicks could be drawn per axis drew them so
_FALLS_KEY = "terminate"  # the key an entry's metadata records Recipe.falls under (its option: train --terminate)

PUSH_KINDS = ("force", "kick")
"""``force``: the paper's pushes (up to the preset's largest force, 0.1-0.3 s, every 1-3 s); ``kick``: velocity
kicks (:class:`Recipe`)."""


@dataclass(frozen=True, kw_only=True)
class Recipe:
    """The robustness levers of a training run (the defaults: the shipped library's recipe)."""

    push_kind: str = "kick"
    """``force`` (the paper's pushes, up to the preset's ``push_max`` N) or ``kick`` (velocity kicks)."""
    kick_max: float = 1.0
    """With ``kick``: the largest change of speed a kick gives along each horizontal axis (``axes``) or in all
    (``disk``), m/s (legged_gym: 1.0 per axis)."""
    kick_draw: str = "axes"
    """With ``kick``: ``axes`` (each horizontal axis uniform in [-kick_max, kick_max], the field's way) or ``disk``
    (a random direction, the magnitude uniform in [0, kick_max])."""
    kick_interval: tuple[float, float] = (1.0, 3.0)
    """With ``kick``: the quiet time before each kick, uniform in this range, s (mjlab: 1-3; legged_gym: 15)."""
    falls: Falls = Falls.TRUNK
    """What ends a training episode as a fall (``train --terminate``; recorded as ``terminate``): ``contact`` (any
    non-foot body on the ground, the paper's) or ``trunk`` (the trunk too low, tilted or on the ground; a leg's touch
    ridden through)."""
    contact_penalty: float = 5.0
    """Reward taken off per control step while a non-foot body touches the ground (the imitation reward lies in
    [0, 1] per step), >= 0."""
    gamma: float | None = 0.99
    """PPO discount (``None``: the preset's, the paper's 0.95; rsl-rl's locomotion tasks: 0.99)."""
    lam: float | None = 0.95
    """GAE lambda (``None``: the preset's, 0.95)."""
    action_delay: int | None = None
    """Control steps every training action waits, fixed (``None``: Table 1's random 0-1)."""
    critic_delay: bool = False
    """The critic sees each world's action delay (privileged; the actor does not): the value of a state no longer
    averages over delays the policy cannot observe."""
    cycle_sync: bool = False
    """The reference's trunk re-anchored horizontally where the robot's is at the start of every gait cycle
    (:attr:`gaitlib.envs.EnvConfig.cycle_sync`; the reward only)."""

    def __post_init__(self) -> None:
        if self.push_kind not in PUSH_KINDS:
            raise GaitlibError(f"--push-kind takes {' or '.join(PUSH_KINDS)}, got '{self.push_kind}'")
        if self.kick_draw not in PUSH_DRAWS:
            raise GaitlibError(f"--kick-draw takes {' or '.join(PUSH_DRAWS)}, got '{self.kick_draw}'")
        low, high = self.kick_interval
        if not (math.isfinite(self.kick_max) and 0 <= self.kick_max <= 5 and 0 < low <= high <= 60):
            raise GaitlibError("kicks: --kick-max in [0, 5] m/s, --kick-interval LOW:HIGH with 0 < LOW <= HIGH <= 60 s")
        if not (math.isfinite(self.contact_penalty) and 0 <= self.contact_penalty <= 10):
            raise GaitlibError(f"--contact-penalty must lie in [0, 10] per step, got {self.contact_penalty:g}")
        for name in ("gamma", "lam"):
            value = getattr(self, name)
            if value is not None and not 0 < value <= 1:
                raise GaitlibError(f"--{name} must lie in (0, 1], got {value:g}")
        if self.action_delay is not None and not 0 <= self.action_delay <= 3:
            raise GaitlibError(f"--action-delay must be 0-3 control steps, got {self.action_delay}")

    def preset(self, preset: TrainPreset) -> TrainPreset:
        """``preset`` with this recipe's discount and lambda."""
        changes = {k: v for k, v in (("gamma", self.gamma), ("lam", self.lam)) if v is not None}
        return dataclasses.replace(preset, **changes)

    def env_config(self, cfg: EnvConfig, *, control_dt: float) -> EnvConfig:
        """``cfg`` with this recipe's pushes (off: the curriculum raises them, :meth:`push_limit`), terminations,
        contact penalty, action delay and cycle sync. A catch task's orientation termination is its tilt alone (a
        catch may turn the robot whichever way it must)."""
        pushes = PushConfig(max_force=0.0)
        if self.push_kind == "kick":
            pushes = PushConfig(max_force=0.0, duration=(control_dt, control_dt), interval=self.kick_interval,
                                draw=self.kick_draw)
        randomization = cfg.randomization
        if self.action_delay is not None:
            randomization = dataclasses.replace(randomization, action_delay_steps=(self.action_delay,) * 2)
        return dataclasses.replace(
            cfg, pushes=pushes, termination=TerminationConfig().counting(self.falls, heading=cfg.task != "catch"),
            contact_penalty=self.contact_penalty, randomization=randomization, cycle_sync=self.cycle_sync,
            observation=dataclasses.replace(cfg.observation, critic_delay=self.critic_delay),
        )

    def push_limit(self, preset: TrainPreset, iteration: int, iterations: int, *, control_dt: float) -> float:
        """The largest push force during ``iteration`` of a run of ``iterations``, N: the preset's curriculum for
        ``force``; for ``kick``, the force that gives the nominal A1 the curriculum's share of :attr:`kick_max` in one
        control step (per axis with the ``axes`` draw)."""
        if self.push_kind == "force":
            return preset.push_limit(iteration, iterations)
        return TOTAL_MASS * self.kick_max * preset.push_share(iteration, iterations) / control_dt

    def as_dict(self) -> dict:
        """What the entry's metadata records (the definition of a fall under its recorded key, ``terminate``)."""
        recorded = dataclasses.asdict(self) | {"falls": self.falls.value}
        return {(_FALLS_KEY if k == "falls" else k): v for k, v in recorded.items()}

    @classmethod
    def from_record(cls, record: dict) -> Recipe:
        """The recipe an entry's metadata records (:meth:`as_dict`), also one recorded before ``kick_draw`` and
        ``cycle_sync`` existed."""
        fields = {"kick_draw": _KICK_DRAW_BEFORE_ITS_OPTION, "cycle_sync": False}
        fields |= {("falls" if k == _FALLS_KEY else k): v for k, v in record.items()}
        return cls(**{**fields, "kick_interval": tuple(fields.get("kick_interval", cls.kick_interval)),
                      "falls": Falls(fields.get("falls", cls.falls))})


PAPER_RECIPE = Recipe(push_kind="force", falls=Falls.CONTACT, contact_penalty=0.0, gamma=None, lam=None)
"""The recipe of the libraries shipped before the robust one (``library-paper/``, ``library-switch-start/``) and the
robust recipe's ablation baseline ("today's"): the paper's pushes, an episode ended on any non-foot body's touch, no
contact penalty, the preset's discount."""
