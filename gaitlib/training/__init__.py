"""Training gait policies with rsl-rl PPO, the library they are saved in, and their evaluation."""

from gaitlib.training.layout import default_library_dir, gait_order
from gaitlib.training.library import Library, LibraryEntry, LibraryError
from gaitlib.training.presets import TrainPreset, get_preset, preset_names

__all__ = [
    "Library",
    "LibraryEntry",
    "LibraryError",
    "TrainPreset",
    "default_library_dir",
    "gait_order",
    "get_preset",
    "preset_names",
]
