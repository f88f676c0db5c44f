"""What training reports of each iteration: the statistics the progress display shows, gathered from rsl-rl's
``learn`` by a logger that prints nothing, and the TensorBoard scalars."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

__all__ = ["IterationLog", "IterationStats", "write_scalars"]


@dataclass(frozen=True)
class IterationStats:
    """What the progress display shows after each iteration."""

    iteration: int
    total: int
    samples: int
    """Environment steps so far, all worlds."""
    samples_per_s: float
    """Throughput of the last iteration (collection and update)."""
    elapsed: float
    """Wall-clock training time so far, s (resumed runs included)."""
    mean_reward: float
    """Mean per-step reward over the last iteration."""
    mean_episode_length: float
    """Mean length of episodes finished in the last iteration, s (NaN if none finished)."""
    reward_terms: dict[str, float]
    """Mean of each imitation reward term over the last iteration."""
    losses: dict[str, float]
    """PPO losses of the update."""


class IterationLog(Logger):
    """Sums what rsl-rl's ``learn`` reports of one iteration, for :class:`IterationStats`. It takes the place of
    rsl-rl's ``Logger``, whose ``log`` prints a report to the console (gaitlib prints only in its CLI); with no log
    folder the base class opens no writer and stores no code state."""

    def __init__(self, runner: OnPolicyRunner) -> None:
        super().__init__(
            log_dir=None,
            cfg=runner.cfg,
            env_cfg=runner.env.cfg,
            num_envs=runner.env.num_envs,
            is_distributed=runner.is_distributed,
            gpu_world_size=runner.gpu_world_size,
            gpu_global_rank=runner.gpu_global_rank,
            device=runner.device,
        )
        self._env = runner.env
        self.clear()

    def clear(self) -> None:
        """Forget the last iteration."""
        self.steps, self.reward_sum, self.seconds = 0, 0.0, 0.0
        self.finished_s: list[float] = []
        self.term_sums: dict[str, float] = {}
        self.losses: dict[str, float] = {}

    def process_env_step(
        self, rewards: torch.Tensor, dones: torch.Tensor, extras: dict, intrinsic_rewards: torch.Tensor | None = None
    ) -> None:
        """Add one control step of all worlds: mean reward, finished episodes' lengths, reward terms."""
        self.steps += 1
        self.reward_sum += float(rewards.mean())
        if dones.any():
            self.finished_s += (self._env.last_episode_length[dones] * self._env.dt).tolist()
        for key, value in extras["log"].items():
            if key.startswith("/reward/"):
                name = key.removeprefix("/reward/")
                self.term_sums[name] = self.term_sums.get(name, 0.0) + float(value)

    def log(self, *, collect_time: float, learn_time: float, loss_dict: dict, **_) -> None:
        """Keep the iteration's time (collection and update, s) and PPO losses."""
        self.seconds = collect_time + learn_time
        self.losses = {name: float(value) for name, value in loss_dict.items()}


def write_scalars(writer, stats: IterationStats) -> None:
    """Write the iteration's statistics to the TensorBoard ``writer`` (``train/``, ``reward/``, ``loss/``)."""
    step = stats.iteration
    writer.add_scalar("train/mean_reward", stats.mean_reward, step)
    writer.add_scalar("train/samples_per_s", stats.samples_per_s, step)
    writer.add_scalar("train/wall_clock_s", stats.elapsed, step)
    if not math.isnan(stats.mean_episode_length):
        writer.add_scalar("train/mean_episode_length_s", stats.mean_episode_length, step)
    for name, value in stats.reward_terms.items():
        writer.add_scalar(f"reward/{name}", value, step)
    for name, value in stats.losses.items():
        writer.add_scalar(f"loss/{name}", value, step)
