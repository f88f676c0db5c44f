"""Train one gait with rsl-rl PPO on rsl-rl's own runner: progress per iteration, TensorBoard, atomic checkpoints,
resume, Ctrl-C, then evaluation and the library entry.

:class:`GaitRunner` subclasses ``rsl_rl.runners.OnPolicyRunner`` (as mjlab's ``rl/runner.py`` does,
https://github.com/mujocolab/mjlab): rollout, returns and the PPO update are rsl-rl's ``learn``, called for one
iteration at a time so that gaitlib can report, checkpoint and stop between iterations. Checkpoints keep the layout
of rsl-rl's ``save`` (the algorithm's state, ``iter``, ``infos``) with gaitlib's run record in ``infos``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

from gaitlib.atomic import atomic_path
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.gaits import GaitDescription, ReferenceClip, clip_from_description
from gaitlib.sim import make_backend, resolve_backend_name
from gaitlib.training.evaluate import EvalResult, evaluate_policy
from gaitlib.training.library import Library
from gaitlib.training.policy import GaitPolicy
from gaitlib.training.presets import TrainPreset, rsl_rl_config

__all__ = ["GaitRunner", "IterationStats", "TrainRequest", "TrainResult", "train_gait"]

_CURVE_ROWS = 60
"""About how many learning-curve rows the entry's metadata keeps (the last one always)."""


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


class _IterationLog(Logger):
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


class GaitRunner(OnPolicyRunner):
    """rsl-rl's on-policy runner for one :class:`TrainRequest`. ``current_learning_iteration`` counts the
    iterations completed (resumed runs included), which is also the ``iter`` its checkpoints record."""

    def __init__(self, env: ImitationEnv, request: TrainRequest) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the model structure
            super().__init__(env, rsl_rl_config(request.preset), log_dir=None, device=str(env.device))
        self.logger = _IterationLog(self)
        self.request = request
        """The run."""
        self.samples = 0
        """Environment steps so far, all worlds (resumed runs included)."""
        self.elapsed = 0.0
        """Training time so far, s (resumed runs included)."""
        self.curve: list[list] = []
        """Learning-curve rows: iteration, training time s, mean reward, mean episode s (None: none ended)."""

    @property
    def checkpoints(self) -> Path:
        """The run's checkpoint folder (``latest.pt``, ``model_<iterations>.pt``)."""
        return self.request.run_dir / "checkpoints"

    def save(self, path: str, infos: dict | None = None) -> None:
        """rsl-rl's checkpoint layout, written atomically: a failed write leaves the old file as it was."""
        state = self.alg.save() | {"iter": self.current_learning_iteration, "infos": infos}
        with atomic_path(Path(path)) as tmp:
            torch.save(state, tmp)

    def checkpoint(self, name: str = "latest.pt") -> None:
        """Save the run under ``checkpoints/name`` with its record (gait, preset, seed, samples, time, curve)."""
        record = {
            "gait": self.request.description.name,
            "preset": self.request.preset.name,
            "seed": self.request.seed,
            "samples": self.samples,
            "elapsed_s": self.elapsed,
            "curve": self.curve,
        }
        self.save(str(self.checkpoints / name), record)

    def resume(self) -> None:
        """Continue from ``checkpoints/latest.pt``; a missing, damaged or foreign checkpoint, or one of another gait
        or preset, is refused in one line."""
        latest = self.checkpoints / "latest.pt"
        saved = _read_checkpoint(latest, device=self.device)
        record = saved["infos"]
        gait, preset = self.request.description.name, self.request.preset.name
        if (record["gait"], record["preset"]) != (gait, preset):
            raise GaitlibError(
                f"checkpoint {latest} is for gait '{record['gait']}' with preset '{record['preset']}', "
                f"not '{gait}' with '{preset}'"
            )
        try:
            self.alg.load(saved, None, strict=True)
        except (KeyError, RuntimeError, TypeError, ValueError) as error:
            raise GaitlibError(
                f"checkpoint {latest} does not fit the preset's networks ({str(error).splitlines()[0][:120]}); "
                "train afresh without --resume"
            ) from error
        self.current_learning_iteration = saved["iter"]
        self.samples, self.elapsed, self.curve = record["samples"], record["elapsed_s"], record["curve"]

    def iterate(self) -> IterationStats:
        """One rsl-rl iteration (rollout, returns, PPO update); its statistics, also added to the curve."""
        log = self.logger
        log.clear()
        self.env.set_push_max(self.request.preset.push_max(self.current_learning_iteration))
        super().learn(1)  # leaves current_learning_iteration at this iteration's index
        self.current_learning_iteration += 1
        step_samples = self.env.num_envs * log.steps
        self.samples += step_samples
        self.elapsed += log.seconds
        stats = IterationStats(
            iteration=self.current_learning_iteration,
            total=self.request.iterations,
            samples=self.samples,
            samples_per_s=step_samples / log.seconds,
            elapsed=self.elapsed,
            mean_reward=log.reward_sum / log.steps,
            mean_episode_length=sum(log.finished_s) / len(log.finished_s) if log.finished_s else math.nan,
            reward_terms={name: total / log.steps for name, total in log.term_sums.items()},
            losses=log.losses,
        )
        length = None if math.isnan(stats.mean_episode_length) else round(stats.mean_episode_length, 2)
        self.curve.append([stats.iteration, round(self.elapsed, 1), round(stats.mean_reward, 4), length])
        return stats

    def train(self, *, on_iteration: Callable[[IterationStats], None] | None = None) -> None:
        """Iterate up to the request's iteration count or time limit, writing TensorBoard scalars to the run folder;
        checkpoint every ``checkpoint_every`` iterations, at the end, and on Ctrl-C (then re-raise)."""
        from torch.utils.tensorboard import SummaryWriter

        request = self.request
        writer = SummaryWriter(log_dir=str(request.run_dir))
        try:
            while self.current_learning_iteration < request.iterations:
                stats = self.iterate()
                _log(writer, stats)
                if on_iteration is not None:
                    on_iteration(stats)
                if stats.iteration % request.checkpoint_every == 0:
                    self.checkpoint()
                    self.checkpoint(f"model_{stats.iteration}.pt")
                if request.time_limit_s is not None and self.elapsed >= request.time_limit_s:
                    break
        except KeyboardInterrupt:
            self.checkpoint()
            raise
        finally:
            writer.close()
        self.checkpoint()


def train_gait(request: TrainRequest, *, on_iteration: Callable[[IterationStats], None] | None = None) -> TrainResult:
    """Train, checkpoint, evaluate and write the library entry; Ctrl-C saves a checkpoint and re-raises."""
    if request.iterations < 1:
        raise GaitlibError(f"--iterations must be positive, got {request.iterations}")
    torch.manual_seed(request.seed)
    preset = request.preset
    clip = clip_from_description(request.description)
    backend_name = resolve_backend_name(request.backend)
    env_cfg = EnvConfig(episode_seconds=preset.episode_seconds, pushes=PushConfig(max_force=preset.push_max(0)))
    sim = make_backend(backend_name, num_worlds=preset.num_envs)
    try:
        runner = GaitRunner(ImitationEnv(sim, [clip], env_cfg, seed=request.seed), request)
        if request.resume:
            runner.resume()
        runner.train(on_iteration=on_iteration)
    finally:
        sim.close()
    return _finish(runner, clip, backend_name, env_cfg)


def _finish(runner: GaitRunner, clip: ReferenceClip, backend_name: str, env_cfg: EnvConfig) -> TrainResult:
    """Evaluate the trained policy and write it, with its run record, into the library."""
    request, preset, alg = runner.request, runner.request.preset, runner.alg
    alg.eval_mode()
    evaluation = evaluate_policy(
        GaitPolicy(alg.get_policy(), alg.critic),
        clip,
        env_cfg=env_cfg,
        episodes=request.eval_episodes,
        seconds=request.eval_seconds,
        backend=backend_name,
        seed=request.seed + 1,
    )
    entry = Library(request.library).save_entry(
        description=request.description,
        actor=alg.get_policy(),
        critic=alg.critic,
        networks={
            "actor_hidden": list(preset.actor_hidden),
            "critic_hidden": list(preset.critic_hidden),
            "activation": preset.activation,
        },
        action={"type": "residual_to_reference", "scale": env_cfg.action_scale, "clip": env_cfg.action_clip},
        observation=env_cfg.observation,
        training={
            "preset": dataclasses.asdict(preset),
            "backend": backend_name,
            "iterations": runner.current_learning_iteration,
            "samples": runner.samples,
            "wall_clock_s": round(runner.elapsed, 1),
            "seed": request.seed,
            "push_force_max_n": preset.push_max(runner.current_learning_iteration),
            "push_ramp_iterations": preset.push_ramp_iterations,
            "randomization": dataclasses.asdict(env_cfg.randomization),
            "episode_seconds": preset.episode_seconds,
            "curve": {
                "columns": ["iteration", "wall_clock_s", "mean_reward", "mean_episode_s"],
                "rows": _thin_curve(runner.curve),
            },
        },
        evaluation=evaluation.as_dict(),
    )
    return TrainResult(
        entry=entry,
        iterations=runner.current_learning_iteration,
        samples=runner.samples,
        wall_clock_s=runner.elapsed,
        evaluation=evaluation,
    )


_RECORD = {"gait": str, "preset": str, "samples": int, "elapsed_s": (int, float), "curve": list}
"""The run record a gaitlib checkpoint keeps in ``infos``: key -> type."""


def _read_checkpoint(path: Path, *, device: str) -> dict:
    """The checkpoint at ``path`` (tensors and plain data only: ``weights_only``), with a complete run record; a
    one-line :class:`GaitlibError` for a missing, truncated or foreign file."""
    if not path.is_file():
        raise GaitlibError(f"nothing to resume: no checkpoint at {path}")
    try:
        saved = torch.load(path, map_location=device, weights_only=True)
    except Exception as error:  # torch raises several unrelated types for a truncated or foreign file
        raise GaitlibError(
            f"checkpoint {path} is unreadable (truncated, or not a plain torch checkpoint); "
            "train afresh without --resume"
        ) from error
    record = saved.get("infos") if isinstance(saved, dict) else None
    complete = isinstance(record, dict) and all(isinstance(record.get(k), t) for k, t in _RECORD.items())
    if not (complete and isinstance(saved.get("iter"), int)):
        raise GaitlibError(
            f"checkpoint {path} is not a gaitlib training checkpoint (no complete run record); "
            "train afresh without --resume"
        )
    return saved


def _thin_curve(rows: list[list], *, most: int = _CURVE_ROWS) -> list[list]:
    """Every k-th row of a learning curve (about ``most`` rows) and the last row, each once."""
    kept = rows[:: max(1, len(rows) // most)]
    return kept if kept[-1:] == rows[-1:] else kept + rows[-1:]


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
