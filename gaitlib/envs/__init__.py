"""The imitation environment and its parts: observations, rewards, terminations,
randomization and pushes, per-world reference tracking."""

from gaitlib.envs.imitation_env import EnvConfig, ImitationEnv

__all__ = ["EnvConfig", "ImitationEnv"]
