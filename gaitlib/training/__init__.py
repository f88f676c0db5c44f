"""Training gait policies with rsl-rl PPO into a library (:mod:`gaitlib.library`), each evaluated as it is written
(:mod:`gaitlib.evaluation`)."""

from gaitlib.training.presets import TrainPreset, get_preset, preset_names

__all__ = ["TrainPreset", "get_preset", "preset_names"]
