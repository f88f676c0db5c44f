"""A library entry made as another's left-right mirror image (``gaitlib mirror``), not trained: the source's weights
mirrored (:func:`gaitlib.library.mirror.mirror_state`) into rsl-rl's actor and critic, written by
:meth:`~gaitlib.library.Library.save_entry` as a trained entry is, ``policy.onnx`` exported from them.

The new entry's gait must be described (a registered description) as the mirror image of the source's
(:func:`gaitlib.gaits.mirror.mirror_shift`). Its ``training`` record says how it was made (``mirror``: the source,
its identity, the phase shift, the command) beside the randomization the source was trained under (which sets the
action delay it runs with); it holds no evaluation until ``gaitlib eval NAME --record`` gives it one, against the
quality bar as any entry's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from gaitlib.envs.mirror import mirror_maps
from gaitlib.errors import GaitlibError
from gaitlib.gaits import GaitDescription
from gaitlib.gaits.mirror import mirror_description, mirror_shift
from gaitlib.library import Library
from gaitlib.library.entry import LibraryEntry
from gaitlib.library.mirror import mirror_state
from gaitlib.library.target import check_writable, library_writer
from gaitlib.robots import get_robot

__all__ = ["MirrorRequest", "check_mirror", "mirror_entry"]


@dataclass(frozen=True, kw_only=True)
class MirrorRequest:
    """What ``gaitlib mirror`` makes: entry ``name`` of ``library`` as the mirror image of ``source`` of
    ``source_library``."""

    source_library: Path
    source: str
    """The entry mirrored."""
    library: Path
    """The library written into."""
    description: GaitDescription
    """The new entry's gait (its name is the entry's)."""
    replace: bool = False
    """Replace an entry of that name, or write a protected library."""
    command: str = ""
    """The command line, recorded in the entry."""


def check_mirror(request: MirrorRequest) -> tuple[LibraryEntry, float]:
    """The source entry and the phase shift of its mirror image, once everything the request needs is checked; one
    line (:class:`~gaitlib.errors.GaitlibError`) for an unknown source, a description that is not the source's
    mirror image, an entry already there without ``replace``, or a protected library without it."""
    entry = Library(request.source_library).entry(request.source)
    name = request.description.name
    shift = mirror_shift(entry.description, request.description)
    if shift is None:
        image = mirror_description(entry.description, name=name)
        raise GaitlibError(
            f"gait '{name}' is not the mirror image of {request.source}: its description differs from "
            f"{_brief(image)} at every phase shift (gaitlib.gaits.mirror)"
        )
    try:
        mirror_maps(entry.observation, shift=shift)
    except ValueError as error:
        raise GaitlibError(f"{request.source} cannot be mirrored as {name}: {error}") from None
    check_writable(request.library, replace=request.replace, command="gaitlib mirror", what=f"the entry {name}")
    if name in Library(request.library).gaits() and not request.replace:
        raise GaitlibError(f"{request.library} already holds an entry {name}; pass --replace to replace it with the "
                           f"mirror image of {request.source}")
    return entry, shift


def mirror_entry(request: MirrorRequest) -> Path:
    """Write the mirror image of the request's source (checked first: :func:`check_mirror`); return the entry's
    folder."""
    entry, shift = check_mirror(request)
    maps = mirror_maps(entry.observation, shift=shift)
    weights = Library(request.source_library).root / request.source / "policy.pt"
    state = mirror_state(torch.load(weights, map_location="cpu", weights_only=True), maps)
    actor, critic = _models(entry, state)
    training = {"mirror": {
        "source": request.source,
        "source_sha256": entry.identity,
        "source_library": str(request.source_library),
        "source_description": entry.description.record(),
        "phase_shift": shift,
        "command": request.command,
    }}
    randomization = entry.metadata["training"].get("randomization")
    if randomization is not None:
        training["randomization"] = randomization
    with library_writer(request.library, command="gaitlib mirror"):
        return Library(request.library).save_entry(
            description=request.description, actor=actor, critic=critic, networks=entry.metadata["networks"],
            action=entry.action, observation=entry.observation, training=training, evaluation={},
        )


def _models(entry: LibraryEntry, state: dict) -> tuple[torch.nn.Module, torch.nn.Module]:
    """rsl-rl's actor and critic of ``entry``'s sizes, ``state`` loaded (what training hands the store)."""
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    cfg, nets = entry.observation, entry.metadata["networks"]
    obs = TensorDict({"policy": torch.zeros(1, cfg.actor_dim), "privileged": torch.zeros(1, cfg.privileged_dim)},
                     batch_size=[1])
    groups = {"actor": ["policy"], "critic": ["policy", "privileged"]}
    std_type = "log" if "distribution.log_std_param" in state["actor"] else "scalar"
    shared = {"activation": nets["activation"]}
    actor = MLPModel(obs, groups, "actor", get_robot(entry.metadata["robot"]).num_joints,
                     hidden_dims=list(nets["actor_hidden"]),
                     obs_normalization=any(k.startswith("obs_normalizer.") for k in state["actor"]),
                     distribution_cfg={"class_name": "rsl_rl.modules.distribution.GaussianDistribution",
                                       "std_type": std_type}, **shared)
    critic = MLPModel(obs, groups, "critic", 1, hidden_dims=list(nets["critic_hidden"]),
                      obs_normalization=any(k.startswith("obs_normalizer.") for k in state["critic"]), **shared)
    actor.load_state_dict(state["actor"])
    critic.load_state_dict(state["critic"])
    return actor.eval(), critic.eval()


def _brief(description: GaitDescription) -> str:
    """A description's phase offsets and velocities in a few words."""
    offsets = ", ".join(f"{o:g}" for o in description.phase_offsets)
    return (f"phase offsets ({offsets}), forward {description.forward_speed:g} m/s, lateral "
            f"{description.lateral_speed:g} m/s, yaw rate {description.yaw_rate:g} rad/s and the rest of the source's "
            "description")
