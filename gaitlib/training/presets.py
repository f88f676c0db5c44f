"""PPO presets for ``gaitlib train``: the paper's (Table 2), one tuned for a 2-core CPU, and a tiny one for tests."""

from __future__ import annotations

from dataclasses import dataclass, replace

from gaitlib.registry import Registry

__all__ = ["TrainPreset", "get_preset", "preset_names", "rsl_rl_config"]


@dataclass(frozen=True, kw_only=True)
class TrainPreset:
    """Everything that sizes a training run: environment count, PPO hyperparameters, network sizes."""

    name: str
    """Registry name."""
    num_envs: int
    """Parallel worlds."""
    steps_per_env: int
    """Control steps per world per iteration (rollout length)."""
    epochs: int
    """PPO epochs per iteration."""
    mini_batches: int
    """Mini-batches per epoch (batch = num_envs * steps_per_env / mini_batches)."""
    learning_rate: float
    """Adam learning rate (adapted by the KL schedule)."""
    gamma: float
    """Discount factor."""
    lam: float
    """GAE lambda."""
    clip: float
    """PPO clip ratio."""
    desired_kl: float
    """KL target of the adaptive learning-rate schedule."""
    entropy_coef: float
    """Entropy bonus."""
    actor_hidden: tuple[int, ...]
    """Actor hidden layer sizes (the last is the latent recorded for transitions)."""
    critic_hidden: tuple[int, ...]
    """Critic hidden layer sizes."""
    init_std: float
    """Initial action standard deviation, action units."""
    iterations: int
    """Default number of iterations."""
    episode_seconds: float = 10.0
    """Training episode length before a time-out, s."""
    push_max: float = 150.0
    """Largest random training push at the end of the curriculum, N (direction random, 0.1-0.3 s, every 1-3 s): a
    gait that rides out 100 N needs to have met more (the benchmark pushes with up to 500 N)."""
    push_ramp: float = 0.4
    """The push curriculum: the largest push grows linearly from 0 to :attr:`push_max` over this fraction of the
    run's iterations (a fall-free start teaches the gait before pushes test it), then stays."""
    activation: str = "elu"
    """Hidden activation."""

    def push_ramp_iterations(self, iterations: int) -> int:
        """Iterations over which the largest push grows, in a run of ``iterations`` iterations."""
        return max(1, round(self.push_ramp * iterations))

    def push_share(self, iteration: int, iterations: int) -> float:
        """How far along the push curriculum iteration ``iteration`` (0-based) of a run of ``iterations`` is, 0-1."""
        return min(1.0, iteration / self.push_ramp_iterations(iterations))

    def push_limit(self, iteration: int, iterations: int) -> float:
        """Largest training push during iteration ``iteration`` (0-based) of a run of ``iterations``, N."""
        return self.push_max * self.push_share(iteration, iterations)

    @property
    def batch_size(self) -> int:
        """Samples per mini-batch."""
        return self.num_envs * self.steps_per_env // self.mini_batches


_PRESETS: Registry[TrainPreset] = Registry("preset")
# Paper Table 2: 4096 envs x 24 steps, 5 epochs, 8 mini-batches of 12288, lr 3e-4, gamma/lambda 0.95,
# clip 0.2, KL 0.008, entropy 0. Network sizes are not given there; 512-256-128 is rsl-rl's locomotion default.
_PRESETS.register(
    "paper",
    TrainPreset(
        name="paper",
        num_envs=4096,
        steps_per_env=24,
        epochs=5,
        mini_batches=8,
        learning_rate=3e-4,
        gamma=0.95,
        lam=0.95,
        clip=0.2,
        desired_kl=0.008,
        entropy_coef=0.0,
        actor_hidden=(512, 256, 128),
        critic_hidden=(512, 256, 128),
        init_std=0.5,
        iterations=3000,
    ),
)
# 2-core CPU: fewer worlds and smaller networks. benchmarks/train_presets.py (docs/benchmarks.md) compared
# 128, 256 and 512 worlds and 5x8 updates for 4 min each: 512 worlds learned most per wall-clock second.
_PRESETS.register(
    "cpu",
    TrainPreset(
        name="cpu",
        num_envs=512,
        steps_per_env=24,
        epochs=4,
        mini_batches=4,
        learning_rate=3e-4,
        gamma=0.95,
        lam=0.95,
        clip=0.2,
        desired_kl=0.008,
        entropy_coef=0.0,
        actor_hidden=(256, 128, 64),
        critic_hidden=(256, 128, 64),
        init_std=0.5,
        iterations=1000,
    ),
)
# The tests' preset: the cpu preset shrunk to 4 worlds x 8 steps, one update of one mini-batch and 32-16 networks,
# small enough for the tests to train on the real simulator. Not meant to learn anything.
_PRESETS.register(
    "tiny",
    replace(
        _PRESETS.get("cpu"),
        name="tiny",
        num_envs=4,
        steps_per_env=8,
        epochs=1,
        mini_batches=1,
        actor_hidden=(32, 16),
        critic_hidden=(32, 16),
        iterations=1,
    ),
)


def get_preset(name: str) -> TrainPreset:
    """The preset called ``name``; raises :class:`~gaitlib.errors.UnknownNameError` for an unknown name."""
    return _PRESETS.get(name)


def preset_names() -> list[str]:
    """Names of the presets."""
    return sorted(_PRESETS.names())


def rsl_rl_config(preset: TrainPreset) -> dict:
    """rsl-rl 5.5 ``OnPolicyRunner`` configuration for ``preset``."""
    model = {
        "class_name": "rsl_rl.models.MLPModel",
        "activation": preset.activation,
        "obs_normalization": True,
    }
    return {
        "num_steps_per_env": preset.steps_per_env,
        "save_interval": 10**9,  # gaitlib checkpoints itself
        "obs_groups": {"actor": ["policy"], "critic": ["policy", "privileged"]},
        "multi_gpu": None,
        "check_for_nan": True,
        "actor": model
        | {
            "hidden_dims": list(preset.actor_hidden),
            "distribution_cfg": {
                "class_name": "rsl_rl.modules.distribution.GaussianDistribution",
                "init_std": preset.init_std,
            },
        },
        "critic": model | {"hidden_dims": list(preset.critic_hidden)},
        "algorithm": {
            "class_name": "rsl_rl.algorithms.PPO",
            "num_learning_epochs": preset.epochs,
            "num_mini_batches": preset.mini_batches,
            "clip_param": preset.clip,
            "gamma": preset.gamma,
            "lam": preset.lam,
            "value_loss_coef": 1.0,
            "entropy_coef": preset.entropy_coef,
            "learning_rate": preset.learning_rate,
            "max_grad_norm": 1.0,
            "use_clipped_value_loss": True,
            "schedule": "adaptive",
            "desired_kl": preset.desired_kl,
        },
    }
