"""Train one gait with rsl-rl PPO: periodic and Ctrl-C checkpoints, resume, TensorBoard, result to the library.

The loop is rsl-rl's ``OnPolicyRunner.learn`` (rollout, returns, PPO update) driven step by step so that gaitlib
can report progress, checkpoint atomically and stop cleanly; the algorithm itself is rsl-rl's, unchanged.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.gaits import GaitDescription, clip_from_description
from gaitlib.sim import make_backend, resolve_backend_name
from gaitlib.training.evaluate import EvalResult, evaluate_policy
from gaitlib.training.library import save_entry
from gaitlib.training.policy import GaitPolicy
from gaitlib.training.presets import TrainPreset, rsl_rl_config

__all__ = ["IterationStats", "TrainRequest", "TrainResult", "train_gait"]


@dataclass(frozen=True, kw_only=True)
class TrainRequest:
    """One training run."""

    description: GaitDescription
    """The gait to imitate."""
    preset: TrainPreset
    """Sizes and PPO hyperparameters."""
    iterations: int
    """PPO iterations to run in total (a resumed run continues up to this count)."""
    time_limit_s: float | None = None
    """Stop after the iteration during which this much training time (s, resumed runs included) has passed."""
    library: Path
    """Where the trained entry is written (``library/<gait>/``)."""
    run_dir: Path
    """Checkpoints and TensorBoard logs (``checkpoints/latest.pt``, ``events.*``)."""
    backend: str = "auto"
    """Simulation backend."""
    seed: int = 0
    """Seed of torch and of the environment's random streams."""
    resume: bool = False
    """Continue from ``run_dir/checkpoints/latest.pt``."""
    checkpoint_every: int = 50
    """Iterations between checkpoints."""
    eval_episodes: int = 64
    """Episodes of the evaluation written into the entry's metadata (``gaitlib eval`` runs longer ones)."""
    eval_seconds: float = 20.0
    """Length of those evaluation episodes, s."""


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


@dataclass(frozen=True)
class TrainResult:
    """A finished run."""

    entry: Path
    """The library entry written."""
    iterations: int
    samples: int
    wall_clock_s: float
    evaluation: EvalResult


def train_gait(request: TrainRequest, *, on_iteration: Callable[[IterationStats], None] | None = None) -> TrainResult:
    """Train, checkpoint, evaluate and write the library entry; Ctrl-C saves a checkpoint and re-raises."""
    from rsl_rl.runners import OnPolicyRunner
    from torch.utils.tensorboard import SummaryWriter

    preset = request.preset
    if request.iterations < 1:
        raise GaitlibError(f"--iterations must be positive, got {request.iterations}")
    torch.manual_seed(request.seed)
    clip = clip_from_description(request.description)
    backend_name = resolve_backend_name(request.backend)
    sim = make_backend(backend_name, num_worlds=preset.num_envs)
    env_cfg = EnvConfig(episode_seconds=preset.episode_seconds, pushes=PushConfig(max_force=preset.push_force))
    env = ImitationEnv(sim, [clip], env_cfg, seed=request.seed)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the model structure
        runner = OnPolicyRunner(env, rsl_rl_config(preset), log_dir=None, device=str(env.device))
    alg = runner.alg

    checkpoints = request.run_dir / "checkpoints"
    checkpoints.mkdir(parents=True, exist_ok=True)
    latest = checkpoints / "latest.pt"
    start, samples, elapsed = 0, 0, 0.0
    curve: list[list] = []  # learning curve rows: iteration, training time s, mean reward, mean episode s
    if request.resume:
        if not latest.is_file():
            raise GaitlibError(f"nothing to resume: no checkpoint at {latest}")
        saved = torch.load(latest, map_location=str(env.device), weights_only=False)
        if saved["gait"] != request.description.name or saved["preset"] != preset.name:
            raise GaitlibError(
                f"checkpoint {latest} is for gait '{saved['gait']}' with preset '{saved['preset']}', "
                f"not '{request.description.name}' with '{preset.name}'"
            )
        alg.load(saved["alg"], None, strict=True)
        start, samples, elapsed = saved["iteration"], saved["samples"], saved["elapsed"]
        curve = saved["curve"]

    def checkpoint(iteration: int, name: str = "latest.pt") -> None:
        state = {
            "alg": alg.save(),
            "iteration": iteration,
            "samples": samples,
            "elapsed": elapsed,
            "gait": request.description.name,
            "preset": preset.name,
            "seed": request.seed,
            "curve": curve,
        }
        tmp = checkpoints / f".{name}.tmp"
        torch.save(state, tmp)
        os.replace(tmp, checkpoints / name)

    writer = SummaryWriter(log_dir=str(request.run_dir))
    obs = env.get_observations()
    alg.train_mode()
    completed = start  # iterations whose update has been applied
    try:
        for iteration in range(start, request.iterations):
            t0 = time.perf_counter()
            reward_sum, finished_lengths = 0.0, []
            term_sums: dict[str, float] = {}
            with torch.inference_mode():
                for _ in range(preset.steps_per_env):
                    actions = alg.act(obs)
                    obs, rewards, dones, extras = env.step(actions)
                    alg.process_env_step(obs, rewards, dones, extras)
                    reward_sum += float(rewards.mean())
                    if dones.any():
                        finished_lengths += (env.last_episode_length[dones] * env.dt).tolist()
                    for key, value in extras["log"].items():
                        if key.startswith("/reward/"):
                            term_sums[key[8:]] = term_sums.get(key[8:], 0.0) + float(value)
                alg.compute_returns(obs)
            losses = alg.update()
            dt = time.perf_counter() - t0
            step_samples = preset.num_envs * preset.steps_per_env
            samples += step_samples
            elapsed += dt
            completed = iteration + 1
            stats = IterationStats(
                iteration=iteration + 1,
                total=request.iterations,
                samples=samples,
                samples_per_s=step_samples / dt,
                elapsed=elapsed,
                mean_reward=reward_sum / preset.steps_per_env,
                mean_episode_length=sum(finished_lengths) / len(finished_lengths) if finished_lengths else float("nan"),
                reward_terms={k: v / preset.steps_per_env for k, v in term_sums.items()},
                losses={k: float(v) for k, v in losses.items()},
            )
            _log(writer, stats)
            length = stats.mean_episode_length
            curve.append(
                [
                    stats.iteration,
                    round(elapsed, 1),
                    round(stats.mean_reward, 4),
                    None if math.isnan(length) else round(length, 2),
                ]
            )
            if on_iteration is not None:
                on_iteration(stats)
            if completed % request.checkpoint_every == 0:
                checkpoint(completed)
                checkpoint(completed, f"model_{completed}.pt")
            if request.time_limit_s is not None and elapsed >= request.time_limit_s:
                break
    except KeyboardInterrupt:
        checkpoint(completed)
        writer.close()
        sim.close()
        raise
    checkpoint(completed)
    writer.close()
    sim.close()

    alg.eval_mode()
    policy = GaitPolicy(alg.get_policy(), alg.critic)
    evaluation = evaluate_policy(
        policy,
        clip,
        action_scale=env_cfg.action_scale,
        episodes=request.eval_episodes,
        seconds=request.eval_seconds,
        backend=backend_name,
        seed=request.seed + 1,
    )
    entry = save_entry(
        request.library,
        description=request.description,
        actor=alg.get_policy(),
        critic=alg.critic,
        networks={
            "actor_hidden": list(preset.actor_hidden),
            "critic_hidden": list(preset.critic_hidden),
            "activation": preset.activation,
        },
        action={"type": "residual_to_reference", "scale": env_cfg.action_scale, "clip": env_cfg.action_clip},
        training={
            "preset": dataclasses.asdict(preset),
            "backend": backend_name,
            "iterations": completed,
            "samples": samples,
            "wall_clock_s": round(elapsed, 1),
            "seed": request.seed,
            "push_force_max_n": preset.push_force,
            "episode_seconds": preset.episode_seconds,
            "curve": {
                "columns": ["iteration", "wall_clock_s", "mean_reward", "mean_episode_s"],
                "rows": curve[:: max(1, len(curve) // 60)] + curve[-1:],
            },
        },
        evaluation=evaluation.as_dict(),
    )
    return TrainResult(entry=entry, iterations=completed, samples=samples, wall_clock_s=elapsed, evaluation=evaluation)


def _log(writer, stats: IterationStats) -> None:
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
