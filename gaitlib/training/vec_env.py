"""The imitation environment seen through rsl-rl's ``VecEnv`` contract, for training only.

rsl-rl's runner and PPO read observations as a ``TensorDict`` of groups (``policy``, ``privileged``); the environment
builds :class:`~gaitlib.envs.observations.ObservationBatch`, so that every command that runs policies without training
them starts without importing rsl-rl or TensorDict. This adapter converts at the boundary; every other attribute is
the environment's own.
"""

from __future__ import annotations

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from gaitlib.envs import ImitationEnv
from gaitlib.envs.observations import ObservationBatch

__all__ = ["RslRlEnv"]


def _groups(obs: ObservationBatch) -> TensorDict:
    return TensorDict({"policy": obs.policy, "privileged": obs.privileged}, batch_size=[len(obs)])


class RslRlEnv(VecEnv):
    """An :class:`~gaitlib.envs.ImitationEnv` as an rsl-rl ``VecEnv`` (observation groups ``policy`` and
    ``privileged``)."""

    def __init__(self, env: ImitationEnv) -> None:
        self.env = env  # num_envs, num_actions, device, max_episode_length, cfg: the environment's own

    @property
    def episode_length_buf(self) -> torch.Tensor:
        """(N,) control steps of each world's episode so far (the environment's; rsl-rl may set it)."""
        return self.env.episode_length_buf

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        self.env.episode_length_buf = value

    def get_observations(self) -> TensorDict:
        return _groups(self.env.get_observations())

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        obs, rewards, dones, extras = self.env.step(actions)
        return _groups(obs), rewards, dones, extras

    def __getattr__(self, name: str):
        if name == "env":  # not set yet (a copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.env, name)
