"""How well a gait takes over from another gait's robot: worlds handed over from recorded states of a source gait
(``gaitlib states``), exactly as a switch hands a robot over, at a uniformly random destination phase, then run on
the gait's own policy for the success horizon. No switching model decides the moment: a switch at random moments,
the measure of the gait itself (the switch-start training it was given shows here)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.handover import HandoverStates
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import FallTally, TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.gaits import ReferenceClip
from gaitlib.library.policy import GaitPolicy
from gaitlib.sim import make_backend
from gaitlib.stats import wilson_interval

__all__ = ["SwitchIn", "switch_in"]


@dataclass(frozen=True)
class SwitchIn:
    """Switches into a gait from one source gait's recorded states."""

    source: str
    """The gait the robots were handed over from."""
    episodes: int
    horizon_s: float
    """Time after the handover within which no fall makes a success, s."""
    falls: int
    fall_ci95: tuple[float, float]
    """Wilson 95% interval of ``falls / episodes``."""
    touches: int
    """Episodes in which a non-foot body touched the ground while up."""
    touch_ci95: tuple[float, float]
    longest_touch_s: float
    falls_definition: Falls

    def as_dict(self) -> dict:
        return asdict(self)


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
        dev, n = env.device, env.num_envs
        env.hand_over(torch.arange(n, device=dev), states.select(chosen), torch.rand(n, generator=gen))
        alive, tally = torch.ones(n, dtype=torch.bool, device=dev), FallTally(n, dev)
        obs = env.get_observations()
        with torch.inference_mode():
            for _ in range(round(horizon_s / env.dt)):
                obs, _, dones, extras = env.step(policy.act(obs))
                tally.step(dones, extras, alive)
                alive &= ~dones
        dt = env.dt
    finally:
        sim.close()
    down, touches = int(tally.fell.sum()), int(tally.touched.sum())
    return SwitchIn(source, n, horizon_s, down, wilson_interval(down, n), touches, wilson_interval(touches, n),
                    float(tally.longest.max()) * dt, falls)
