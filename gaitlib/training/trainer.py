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
from dataclasses import dataclass, field
from pathlib import Path

import torch
from rsl_rl.runners import OnPolicyRunner

from gaitlib.atomic import release_lock, take_lock, torch_bytes, write_bytes
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.catch import CATCH_EPISODE_S
from gaitlib.envs.handover import HandoverStates
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import EvalResult, evaluate_policy
from gaitlib.gaits import GaitDescription, ReferenceClip, clip_from_description
from gaitlib.library.policy import GaitPolicy
from gaitlib.library.store import Library
from gaitlib.library.target import copy_library, library_writer
from gaitlib.sim import make_backend, resolve_backend_name
from gaitlib.training.checkpoint import check_same_run, read_checkpoint, run_identity, start_over
from gaitlib.training.distributed import Ranks, agree, join, leave, parameters_in_sync, rank_device
from gaitlib.training.iteration_log import IterationLog, IterationStats, write_scalars
from gaitlib.training.presets import TrainPreset, rsl_rl_config
from gaitlib.training.recipe import Recipe
from gaitlib.training.switch_start import handover_states
from gaitlib.training.target import check_target
from gaitlib.training.vec_env import RslRlEnv

__all__ = ["GaitRunner", "IterationStats", "TrainRequest", "TrainResult", "resume_point", "train_gait"]

_CURVE_ROWS = 60
"""About how many learning-curve rows the entry's metadata keeps (the last one always)."""


@dataclass(frozen=True, kw_only=True)
class TrainRequest:
    """One training run."""

    description: GaitDescription
    """The gait to imitate, or (its task ``catch``) the catch skill to train from :attr:`states`."""
    preset: TrainPreset
    """Sizes and PPO hyperparameters."""
    iterations: int
    """PPO iterations to run in total (a resumed run continues up to this count)."""
    time_limit_s: float | None = None
    """Stop after the iteration during which this much training time (s, resumed runs included) has passed."""
    library: Path
    """Where the trained entry is written (``library/<gait>/``; :mod:`gaitlib.training.target`)."""
    copy_from: Path | None = None
    """A library copied into :attr:`library` before the entry is written, when :attr:`library` does not exist yet
    (the shipped library, for the user's own library's first write)."""
    replace: bool = False
    """Replace the entry of this gait in the shipped library (refused otherwise, before any work)."""
    states: Path | None = None
    """Handover states of other gaits (``gaitlib states``; :mod:`gaitlib.envs.handover`) that a share of the
    training episodes start from; ``None``: every episode starts from the reference (the paper's recipe)."""
    switch_start: float = 0.0
    """The share of training episodes (resets) that start from a handover state, in [0, 1] (0: the paper's
    recipe)."""
    recipe: Recipe = field(default_factory=Recipe)
    """The robustness levers: pushes, terminations, contact penalty, discount, action delay (the defaults: the
    shipped library's recipe; the preset given is the one trained with, its discount already the recipe's)."""
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
class TrainResult:
    """A finished run."""

    entry: Path
    """The library entry written."""
    iterations: int
    samples: int
    wall_clock_s: float
    evaluation: EvalResult


class GaitRunner(OnPolicyRunner):
    """rsl-rl's on-policy runner for one :class:`TrainRequest`. ``current_learning_iteration`` counts the
    iterations completed (resumed runs included), which is also the ``iter`` its checkpoints record."""

    def __init__(self, env: ImitationEnv, request: TrainRequest) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the model structure
            super().__init__(RslRlEnv(env), rsl_rl_config(request.preset), log_dir=None, device=str(env.device))
        self.logger = IterationLog(self)
        self.request = request
        """The run."""
        self.ranks = Ranks.from_env()
        """This process's place among the training processes (``torchrun``; one process otherwise)."""
        self.samples = 0
        """Environment steps so far, all worlds (resumed runs included)."""
        self.elapsed = 0.0
        """Training time so far, s (resumed runs included)."""
        self.curve: list[list] = []
        """Learning-curve rows: iteration, training time s, mean reward, mean episode s (None: none ended)."""
        self.identity = run_identity(request)
        """What the run trains from, as its checkpoints record it (:mod:`gaitlib.training.checkpoint`)."""

    def _configure_multi_gpu(self) -> None:
        """rsl-rl's own multi-GPU setup for CUDA ranks (NCCL); a CPU rank joins over gloo with the same settings
        (:func:`gaitlib.training.distributed.join`)."""
        if str(self.device).startswith("cuda"):
            super()._configure_multi_gpu()
            return
        ranks = Ranks.from_env()
        self.gpu_world_size, self.is_distributed = ranks.world_size, ranks.distributed
        self.gpu_local_rank, self.gpu_global_rank = ranks.local_rank, ranks.rank
        self.cfg["multi_gpu"] = join(ranks)

    @property
    def checkpoints(self) -> Path:
        """The run's checkpoint folder (``latest.pt``, ``model_<iterations>.pt``)."""
        return self.request.run_dir / "checkpoints"

    def save(self, path: str, infos: dict | None = None) -> None:
        """rsl-rl's checkpoint layout, written atomically: a failed write leaves the old file as it was."""
        state = self.alg.save() | {"iter": self.current_learning_iteration, "infos": infos}
        write_bytes(Path(path), torch_bytes(state))

    def checkpoint(self, name: str = "latest.pt") -> None:
        """Save the run under ``checkpoints/name`` with its record: its identity
        (:func:`~gaitlib.training.checkpoint.run_identity`), world size, samples, time and curve."""
        record = self.identity | {
            "world_size": self.ranks.world_size,
            "samples": self.samples,
            "elapsed_s": self.elapsed,
            "curve": self.curve,
        }
        self.save(str(self.checkpoints / name), record)

    def resume(self, saved: dict) -> None:
        """Continue from ``saved``, the run's latest checkpoint as :func:`train_gait` read and checked it; one that
        does not fit the preset's networks is refused in one line."""
        latest = self.checkpoints / "latest.pt"
        try:
            self.alg.load(saved, None, strict=True)
        except (KeyError, RuntimeError, TypeError, ValueError) as error:
            raise GaitlibError(
                f"checkpoint {latest} does not fit the preset's networks ({str(error).splitlines()[0][:120]}); "
                f"{start_over(latest)}"
            ) from error
        record = saved["infos"]
        self.current_learning_iteration = saved["iter"]
        self.samples, self.elapsed, self.curve = record["samples"], record["elapsed_s"], record["curve"]

    def iterate(self) -> IterationStats:
        """One rsl-rl iteration (rollout, returns, PPO update); its statistics, also added to the curve."""
        log = self.logger
        log.clear()
        request = self.request
        self.env.set_push_max(request.recipe.push_limit(request.preset, self.current_learning_iteration,
                                                        request.iterations, control_dt=self.env.dt))
        with contextlib.redirect_stdout(io.StringIO()) if self.is_distributed else contextlib.nullcontext():
            super().learn(1)  # leaves current_learning_iteration at this iteration's index (and, distributed,
            # prints that it synchronizes the parameters)
        self.current_learning_iteration += 1
        step_samples = self.env.num_envs * log.steps * self.ranks.world_size
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
        checkpoint every ``checkpoint_every`` iterations, at the end, and on Ctrl-C (then re-raise). Distributed,
        rank 0 alone logs, reports and checkpoints, and decides when time is up."""
        from torch.utils.tensorboard import SummaryWriter

        request, main = self.request, self.ranks.main
        writer = SummaryWriter(log_dir=str(request.run_dir)) if main else None
        try:
            while self.current_learning_iteration < request.iterations:
                stats = self.iterate()
                if main:
                    write_scalars(writer, stats)
                    if on_iteration is not None:
                        on_iteration(stats)
                    if stats.iteration % request.checkpoint_every == 0:
                        self.checkpoint()
                        self.checkpoint(f"model_{stats.iteration}.pt")
                late = request.time_limit_s is not None and self.elapsed >= request.time_limit_s
                if agree(late, device=str(self.device)):
                    break
        except KeyboardInterrupt:
            if main:
                self.checkpoint()
            raise
        finally:
            if writer is not None:
                writer.close()
        if main:
            self.checkpoint()


def train_gait(
    request: TrainRequest, *, on_iteration: Callable[[IterationStats], None] | None = None
) -> TrainResult | None:
    """Train, checkpoint, evaluate and write the library entry; Ctrl-C saves a checkpoint and re-raises.

    Under ``torchrun`` every rank trains its own worlds with seed ``request.seed + rank``; rank 0 writes the entry
    and gets the result, the other ranks ``None`` (:mod:`gaitlib.training.distributed`).
    """
    if request.iterations < 1:
        raise GaitlibError(f"--iterations must be positive, got {request.iterations}")
    check_target(
        request.library, request.description.name, preset=request.preset.name, replace=request.replace,
        copy_from=request.copy_from,
    )
    if request.description.task == "catch" and request.states is None:
        raise GaitlibError("a catch task starts its episodes from recorded states: --states FILE (gaitlib states "
                           "--shove-max 30 records them)")
    states = handover_states(request.states, request.switch_start, gait=request.description.name)  # before any file
    ranks = Ranks.from_env()
    if not ranks.main:
        return _train(request, ranks, on_iteration, states, resume_point(request))
    lock = request.run_dir / ".run.lock"
    fd = take_lock(lock, writing=f"training run folder {request.run_dir}", error=GaitlibError)
    try:
        latest = request.run_dir / "checkpoints" / "latest.pt"
        if not request.resume and latest.is_file():
            read_checkpoint(latest, device="cpu")  # one that cannot be resumed says so, not "use --resume"
            raise GaitlibError(
                f"{request.run_dir} belongs to another training run (it holds {latest}); continue that run with "
                f"--resume and the inputs it was started with, or {start_over(latest)}"
            )
        return _train(request, ranks, on_iteration, states, resume_point(request))
    finally:
        release_lock(lock, fd)


def resume_point(request: TrainRequest) -> dict | None:
    """With ``request.resume``: the run's latest checkpoint, read and shown to be of this very run (every input the
    same: :func:`~gaitlib.training.checkpoint.check_same_run`) before any simulation is built; else ``None``."""
    if not request.resume:
        return None
    latest = request.run_dir / "checkpoints" / "latest.pt"
    saved = read_checkpoint(latest, device="cpu")
    check_same_run(saved["infos"], run_identity(request), path=latest)
    return saved


def _train(
    request: TrainRequest, ranks: Ranks, on_iteration: Callable[[IterationStats], None] | None,
    handover: tuple[HandoverStates | None, dict | None], saved: dict | None,
) -> TrainResult | None:
    """:func:`train_gait` once its run folder is its own; ``handover``: the states and their record
    (:func:`~gaitlib.training.switch_start.handover_states`); ``saved``: the checkpoint to continue, else ``None``."""
    seed = request.seed + ranks.rank
    torch.manual_seed(seed)
    preset = request.preset
    clip = clip_from_description(request.description)
    backend_name = resolve_backend_name(request.backend)
    states, switch_start = handover
    sim = make_backend(backend_name, num_worlds=preset.num_envs, device=rank_device(backend_name, ranks))
    # Pushes start at 0 N: GaitRunner.iterate raises their largest magnitude along the recipe's curriculum.
    task = request.description.task  # a catch's episodes are its own length (gaitlib.envs.catch)
    seconds = CATCH_EPISODE_S if task == "catch" else preset.episode_seconds
    env_cfg = request.recipe.env_config(EnvConfig(episode_seconds=seconds, task=task), control_dt=sim.control_dt)
    try:
        env = ImitationEnv(
            sim, [clip], env_cfg, seed=seed, handover=states, handover_share=request.switch_start if states else 0.0
        )
        runner = GaitRunner(env, request)
        if saved is not None:
            runner.resume(saved)
        runner.train(on_iteration=on_iteration)
        in_sync = parameters_in_sync(runner.alg.get_policy(), device=str(runner.device))
    finally:
        sim.close()
    try:
        return _finish(runner, clip, backend_name, env_cfg, switch_start, in_sync=in_sync) if ranks.main else None
    finally:
        leave()


def _deployed(runner: GaitRunner) -> GaitPolicy:
    """The trained actor and critic as the library will load them, on the training device."""
    preset, alg = runner.request.preset, runner.alg
    return GaitPolicy.from_state(
        {"actor": alg.get_policy().state_dict(), "critic": alg.critic.state_dict()},
        actor_hidden=preset.actor_hidden,
        critic_hidden=preset.critic_hidden,
        activation=preset.activation,
        num_actions=runner.env.num_actions,
        observation=runner.env.cfg.observation,
    ).to(runner.device)


def _finish(
    runner: GaitRunner, clip: ReferenceClip, backend_name: str, env_cfg: EnvConfig, switch_start: dict | None,
    *, in_sync: bool,
) -> TrainResult:
    """Evaluate the trained policy and write it, with its run record, into the library."""
    request, preset, alg = runner.request, runner.request.preset, runner.alg
    alg.eval_mode()
    evaluation = evaluate_policy(
        _deployed(runner),
        clip,
        env_cfg=env_cfg,
        episodes=request.eval_episodes,
        seconds=request.eval_seconds,
        backend=backend_name,
        seed=request.seed + 1,
    )
    if request.copy_from is not None and not request.library.exists():
        copy_library(request.copy_from, request.library)
    with library_writer(request.library, command="gaitlib train"):  # one writer of the library at a time
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
                "switch_start": switch_start,
                "recipe": request.recipe.as_dict(),
                "push_max_n": request.recipe.push_limit(preset, runner.current_learning_iteration, request.iterations,
                                                        control_dt=runner.env.dt),
                "push_ramp_iterations": preset.push_ramp_iterations(request.iterations),
                "randomization": dataclasses.asdict(env_cfg.randomization),
                "distributed": {"world_size": runner.ranks.world_size, "parameters_in_sync": in_sync},
                "episode_seconds": env_cfg.episode_seconds,
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


def _thin_curve(rows: list[list], *, most: int = _CURVE_ROWS) -> list[list]:
    """Every k-th row of a learning curve (about ``most`` rows) and the last row, each once."""
    kept = rows[:: max(1, len(rows) // most)]
    return kept if kept[-1:] == rows[-1:] else kept + rows[-1:]
