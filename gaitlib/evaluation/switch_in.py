"""How well a gait takes over from another gait's robot: worlds handed over from recorded states of a source gait
(``gaitlib states``), exactly as a switch hands a robot over, at a uniformly random destination phase, then run on
the gait's own policy for the success horizon. No switching model decides the moment: a switch at random moments,
the measure of the gait itself (the switch-start training it was given shows here)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.handover import HandoverStates
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.evaluation.rollout import FallRecord, rollout
from gaitlib.gaits import ReferenceClip
from gaitlib.library.policy import GaitPolicy
from gaitlib.sim import make_backend

__all__ = ["SwitchIn", "switch_in"]


@dataclass(frozen=True, kw_only=True)
class SwitchIn(FallRecord):
    """Switches into a gait from one source gait's recorded states: its falls and touches within the horizon
    (:class:`FallRecord`)."""

    source: str
    """The gait the robots were handed over from."""
    horizon_s: float
    """Time after the handover within which no fall makes a success, s."""

    def as_dict(self) -> dict:
        """The measure as an ablation row records it (the fall count as ``falls``, the definition as
        ``falls_definition``)."""
        return {
            "source": self.source, "episodes": self.episodes, "horizon_s": self.horizon_s, "falls": self.fell,
            "fall_ci95": self.fall_ci95, "touches": self.touched, "touch_ci95": self.touch_ci95,
            "longest_touch_s": self.longest_touch_s, "falls_definition": self.falls.value,
        }


def switch_in(
    policy: GaitPolicy,
    clip: ReferenceClip,
    *,
    env_cfg: EnvConfig,
    states: HandoverStates,
    source: str,
    episodes: int,
    horizon_s: float = 2.5,
    falls: Falls = DEFAULT_FALLS,
    backend: str = "auto",
    seed: int = 0,
) -> SwitchIn:
    """``episodes`` robots of ``source``'s recorded ``states`` (drawn with replacement) handed over to ``policy``'s
    gait at uniform destination phases, under paper Table 1 randomization and no pushes (``env_cfg``: the policy's
    settings), each judged over ``horizon_s`` by the definition of a fall ``falls`` (a turn away from the reference
    counts, as in the benchmark)."""
    if source not in states.gaits or not np.any(states.source == states.gaits.index(source)):
        raise GaitlibError(f"the states hold none recorded while '{source}' ran (they hold {', '.join(states.gaits)})")
    rows = np.flatnonzero(states.source == states.gaits.index(source))
    gen = torch.Generator().manual_seed(seed)
    chosen = rows[torch.randint(len(rows), (episodes,), generator=gen).numpy()]
    cfg = replace(env_cfg, episode_seconds=horizon_s + 1.0, pushes=PushConfig(max_force=0.0),
                  termination=TerminationConfig().counting(falls))
    sim = make_backend(backend, num_worlds=episodes)
    try:
        env = ImitationEnv(sim, [clip], cfg, seed=seed)
        n = env.num_envs
        env.hand_over(torch.arange(n, device=env.device), states.select(chosen), torch.rand(n, generator=gen))
        counted, _ = rollout(env, policy, steps=round(horizon_s / env.dt))
    finally:
        sim.close()
    return SwitchIn(**counted.counted(), source=source, horizon_s=horizon_s)
