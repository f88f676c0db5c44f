"""Training gait policies with rsl-rl PPO, the library entries they are saved as, and their evaluation."""

from gaitlib.training.library import LibraryEntry, LibraryError, default_library_dir, load_entry, save_entry
from gaitlib.training.presets import TrainPreset, get_preset, preset_names

__all__ = [
    "LibraryEntry",
    "LibraryError",
    "TrainPreset",
    "default_library_dir",
    "get_preset",
    "load_entry",
    "preset_names",
    "save_entry",
]
