"""The policy library on disk: one folder per gait, written atomically, checked when read.

``<library>/<gait>/`` holds ``policy.pt`` (actor and critic weights with their observation normalizers),
``policy.onnx`` (the deterministic actor, normalizer included) and ``metadata.json`` (format version, the gait
description, observation and action layout, network sizes, how it was trained and how well it did, versions,
and the SHA-256 of ``policy.pt`` that identifies the entry to transition data and transition-nets).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch

from gaitlib.envs import observations as obs_fn
from gaitlib.errors import GaitlibError
from gaitlib.gaits import GaitDescription, ReferenceClip, clip_from_description
from gaitlib.robots import get_robot
from gaitlib.training.export import export_onnx
from gaitlib.training.policy import GaitPolicy, build_models

__all__ = [
    "FORMAT_VERSION",
    "LibraryEntry",
    "LibraryError",
    "default_library_dir",
    "entry_names",
    "load_entry",
    "save_entry",
]

FORMAT_VERSION = 1
"""Version of the on-disk layout of a library entry; an entry of another version is refused."""


class LibraryError(GaitlibError):
    """A library entry is missing, damaged, or was written for another version or observation layout."""


@dataclass
class LibraryEntry:
    """One trained gait, loaded."""

    name: str
    """Gait name (the folder name)."""
    metadata: dict
    """Everything in ``metadata.json``."""
    policy: GaitPolicy
    """Actor, latent and critic."""
    description: GaitDescription
    """The gait description the policy was trained to imitate."""
    clip: ReferenceClip
    """The reference clip built from :attr:`description`."""

    @property
    def identity(self) -> str:
        """SHA-256 of the weights file: what transition data and transition-nets refer to."""
        return self.metadata["sha256"]

    @property
    def action_scale(self) -> float:
        """PD target = reference + action_scale * action, rad per action unit."""
        return float(self.metadata["action"]["scale"])


def default_library_dir() -> Path:
    """``$GAITLIB_LIBRARY`` if set, else the repository's shipped ``library/`` beside the package."""
    if "GAITLIB_LIBRARY" in os.environ:
        return Path(os.environ["GAITLIB_LIBRARY"])
    return Path(__file__).resolve().parents[2] / "library"


def entry_names(library: Path) -> list[str]:
    """Gaits that have an entry in ``library``."""
    if not library.is_dir():
        return []
    return sorted(p.name for p in library.iterdir() if (p / "metadata.json").is_file())


def save_entry(
    library: Path,
    *,
    description: GaitDescription,
    actor: torch.nn.Module,
    critic: torch.nn.Module,
    networks: dict,
    action: dict,
    training: dict,
    evaluation: dict,
) -> Path:
    """Write ``library/<gait>/`` atomically (into a temporary folder, then renamed over the old entry).

    ``networks``: ``actor_hidden``, ``critic_hidden``, ``activation``; ``action``: ``type``, ``scale``, ``clip``;
    ``training`` and ``evaluation``: free-form records of how the policy was made and how good it is.
    """
    library.mkdir(parents=True, exist_ok=True)
    final = library / description.name
    staging = Path(tempfile.mkdtemp(prefix=f".{description.name}.", dir=library))
    staging.chmod(0o755)  # mkdtemp makes it private; an entry is meant to be shared
    try:
        weights = staging / "policy.pt"
        torch.save({"actor": actor.state_dict(), "critic": critic.state_dict()}, weights)
        export_onnx(actor, staging / "policy.onnx")
        metadata = {
            "format_version": FORMAT_VERSION,
            "gait": description.name,
            "description": dataclasses.asdict(description),
            "robot": "a1",
            "observation": obs_fn.layout(),
            "action": action,
            "networks": networks,
            "training": training,
            "evaluation": evaluation,
            "versions": _versions(),
            "sha256": hashlib.sha256(weights.read_bytes()).hexdigest(),
        }
        (staging / "metadata.json").write_text(json.dumps(metadata, indent=2) + "\n")
        _replace_dir(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return final


def load_entry(library: Path, name: str) -> LibraryEntry:
    """Load and check ``library/<name>/``; raises :class:`LibraryError` with a one-line reason."""
    folder = library / name
    meta_path = folder / "metadata.json"
    if not meta_path.is_file():
        known = ", ".join(entry_names(library)) or "none"
        raise LibraryError(f"no library entry for gait '{name}' in {library} (entries: {known})")
    try:
        metadata = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise LibraryError(f"library entry '{name}' has unreadable metadata: {error}") from error
    if not isinstance(metadata, dict) or metadata.get("format_version") != FORMAT_VERSION:
        version = metadata.get("format_version") if isinstance(metadata, dict) else None
        raise LibraryError(
            f"library entry '{name}' has format version {version}, this gaitlib reads version {FORMAT_VERSION}"
        )
    if metadata.get("observation") != obs_fn.layout():
        raise LibraryError(
            f"library entry '{name}' was trained with another observation layout; retrain it with this gaitlib"
        )
    weights = folder / "policy.pt"
    if not weights.is_file() or hashlib.sha256(weights.read_bytes()).hexdigest() != metadata.get("sha256"):
        raise LibraryError(f"library entry '{name}' is damaged: policy.pt is missing or does not match its checksum")
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
        description = GaitDescription(**metadata["description"])
        nets = metadata["networks"]
        actor, critic = build_models(
            actor_hidden=tuple(nets["actor_hidden"]),
            critic_hidden=tuple(nets["critic_hidden"]),
            activation=nets["activation"],
            num_actions=get_robot(metadata.get("robot", "a1")).num_joints,
        )
        actor.load_state_dict(state["actor"])
        critic.load_state_dict(state["critic"])
    except (KeyError, TypeError, RuntimeError, ValueError) as error:
        raise LibraryError(f"library entry '{name}' cannot be loaded: {error}") from error
    return LibraryEntry(
        name=name,
        metadata=metadata,
        policy=GaitPolicy(actor, critic),
        description=description,
        clip=clip_from_description(description),
    )


def _replace_dir(staging: Path, final: Path) -> None:
    """Swap ``staging`` into place as ``final``; the old entry is removed only after the swap."""
    old = None
    if final.exists():
        old = final.with_name(f".{final.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(final, old)
    os.replace(staging, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _versions() -> dict[str, str]:
    from importlib.metadata import version

    import gaitlib

    return {
        "gaitlib": gaitlib.__version__,
        "torch": torch.__version__,
        "rsl-rl-lib": version("rsl-rl-lib"),
        "mujoco": version("mujoco"),
    }
