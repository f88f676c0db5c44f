"""The library on disk, behind one object (:class:`Library`) that alone knows its layout.

A library folder holds one entry per gait and the switching models fitted on its transition data::

    <library>/<gait>/metadata.json, policy.pt, policy.onnx   one trained gait (see below)
    <library>/switching/net.pt                               the transition-net (gaitlib fit)
    <library>/switching/tmt.json                             the TMT with the strategies' calibrated thresholds
    <library>/switching/accuracy.json                        how well the net and its input ablation did
    <library>/switching/calibration.json                     the net's score mapped to real success rates
    <library>/switching/checksums.json                       the SHA-256 of each file of the folder but itself
    <library>/switching/survival.pt, routes.json             the guard's estimate, the route table (optional)

Each entry and the ``switching`` folder are published whole (:mod:`gaitlib.library.publish`): a reader, or a
writer killed at any moment, finds the old version or the new one, never neither and never a mix (a net beside
the TMT of another fit, say).

Gaits are always in one canonical order, their names sorted (:func:`gait_order`): transition files, the
transition-net's one-hot gait inputs and the TMT's tables index gaits in that order whatever order a user named
them in. Folders whose name starts with ``.`` (staging or replaced folders) are never gaits.

``<library>/<gait>/`` holds ``policy.pt`` (actor and critic weights with their observation normalizers),
``policy.onnx`` (the deterministic actor, normalizer included) and ``metadata.json`` (format version, the gait
description, observation and action layout, network sizes, how it was trained and how well it did, versions,
the SHA-256 of ``policy.pt`` that identifies the entry to transition data and transition-nets, and the
``deployment`` block that lets a policy run from ``policy.onnx`` alone: ``docs/deploying.md``).
"""

from __future__ import annotations

import contextlib
import json
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path

import torch

from gaitlib.atomic import CHECKSUM_KEY, file_sha256, json_checksum, torch_bytes, write_json
from gaitlib.checks import Invalid
from gaitlib.envs import observations as obs_fn
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.gaits import GaitDescription, clip_from_description
from gaitlib.library.checksums import listed_checksums, models_identity, write_listed
from gaitlib.library.deployment import deployment_block
from gaitlib.library.entry import LibraryEntry, PolicySettings
from gaitlib.library.export import export_onnx
from gaitlib.library.layout import (
    check_identities,
    default_library_dir,
    first_fit,
    gait_order,
)
from gaitlib.library.policy import GaitPolicy
from gaitlib.library.publish import recover, staged_folder
from gaitlib.library.validate import check_action, check_deployment, check_metadata
from gaitlib.robots import get_robot

__all__ = [
    "FORMAT_VERSION",
    "Library",
    "LibraryEntry",
    "LibraryError",
    "PolicySettings",
]

FORMAT_VERSION = 2
"""Version of the on-disk layout of a library entry; an entry of another version is refused (2: the ``deployment``
block, and ``policy.onnx`` with a batch axis of any size)."""


class LibraryError(GaitlibError):
    """A library entry is missing, damaged, or was written for another version or observation layout."""


class Library:
    """A library folder: its gait entries (loaded once each), their identities and shared action settings, and where
    its transition-net, accuracy report and TMT live.

    ``root``: the folder (``None``: :func:`default_library_dir`). Nothing is read until asked for.
    """

    SWITCHING = "switching"
    """The folder of the switching models fitted together, relative to the root (published whole)."""
    NET = "net.pt"
    """The transition-net, in :attr:`SWITCHING`."""
    TMT = "tmt.json"
    """The TMT and calibrated thresholds, in :attr:`SWITCHING`."""
    ACCURACY = "accuracy.json"
    """The fit's accuracy report (Table 3 layout), in :attr:`SWITCHING`."""
    CALIBRATION = "calibration.json"
    """The transition-net's score mapped to real success probabilities, in :attr:`SWITCHING`."""
    BUNDLE = (NET, TMT, ACCURACY, CALIBRATION)
    """The files of :attr:`SWITCHING` that are fitted together and checked against :attr:`CHECKSUMS`."""
    CHECKSUMS = "checksums.json"
    """The SHA-256 of each of the other files of :attr:`SWITCHING`, checked before any of them is used."""
    SURVIVAL = "survival.pt"
    """The guard's survival estimate (``gaitlib survival fit``), in :attr:`SWITCHING`, listed in :attr:`CHECKSUMS`:
    made with the policies it records, so a refit keeps it and it reads as stale once the gaits change."""
    ROUTES = "routes.json"
    """The route table (``gaitlib routes``), in :attr:`SWITCHING`: measured with the models of :attr:`BUNDLE`, whose
    checksum list it records, so a refit keeps it and it then reads as stale (:mod:`gaitlib.benchmark.routes`)."""

    def __init__(self, root: Path | str | None = None) -> None:
        self.root = Path(root) if root is not None else default_library_dir()
        """The library folder."""
        self._entries: dict[str, LibraryEntry] = {}

    def __repr__(self) -> str:
        return f"Library({str(self.root)!r})"

    @property
    def switching_dir(self) -> Path:
        return self.root / self.SWITCHING

    @property
    def net_path(self) -> Path:
        return self.switching_dir / self.NET

    @property
    def tmt_path(self) -> Path:
        return self.switching_dir / self.TMT

    @property
    def accuracy_path(self) -> Path:
        return self.switching_dir / self.ACCURACY

    @property
    def calibration_path(self) -> Path:
        return self.switching_dir / self.CALIBRATION

    def check_switching(self) -> None:
        """Refuse, in one line, a library without fitted switching models (with the commands that make them), or
        one whose switching files do not match the checksums written with them (``checksums.json``)."""
        listed = self.listed_checksums()
        for name in self.BUNDLE:
            file = self.switching_dir / name
            if not file.is_file() or file_sha256(file) != listed.get(name):
                raise TransitionDataError(
                    f"{file} is missing or does not match its checksum in {self.switching_dir / self.CHECKSUMS}"
                )

    def listed_checksums(self) -> dict[str, str]:
        """File name -> SHA-256 of the switching files as :attr:`CHECKSUMS` lists them (the models, and the survival
        estimate where there is one: :mod:`gaitlib.library.checksums`); one line for a library without switching
        models, or without a (sound) list."""
        recover(self.switching_dir)
        if not self.switching_dir.is_dir():
            raise TransitionDataError(
                f"library {self.root} has no transition-net and TMT yet; make them: "
                + " && ".join(first_fit(self.root))
            )
        path = self.switching_dir / self.CHECKSUMS
        if not path.is_file():
            raise TransitionDataError(f"{path} is missing: the switching models are unchecked; run gaitlib fit again")
        return listed_checksums(path, error=TransitionDataError)

    def switching_identity(self) -> str | None:
        """SHA-256 of the switching models' checksum list (the four models': a survival estimate's line changes
        nothing), once their files are checked against it (one line if not): what a measurement made with them
        records; ``None`` for a library without switching models."""
        if not self.switching_dir.is_dir():
            return None
        self.check_switching()
        return models_identity(self.listed_checksums(), self.BUNDLE)

    def write_checksums(self, folder: Path, *, survival: str | None = None) -> Path:
        """Write ``checksums.json`` into the switching folder being staged at ``folder`` (after the other files):
        the SHA-256 of each model there and ``survival``, the one listed for the survival estimate (``None``:
        none)."""
        files = {name: file_sha256(folder / name) for name in self.BUNDLE}
        return write_listed(folder / self.CHECKSUMS, files | ({} if survival is None else {self.SURVIVAL: survival}))

    def publish_switching(self) -> contextlib.AbstractContextManager[Path]:
        """A staging folder to write the net, TMT, accuracy report and calibration into (names :attr:`NET`,
        :attr:`TMT`, :attr:`ACCURACY`, :attr:`CALIBRATION`); they replace the library's together when the ``with``
        block ends without an error."""
        return staged_folder(self.switching_dir)

    def gaits(self) -> tuple[str, ...]:
        """Gaits that have an entry, in canonical order (an entry a killed writer left half-replaced is put back
        first: see :mod:`gaitlib.library.publish`)."""
        if not self.root.is_dir():
            return ()
        for old in self.root.glob(".*.old"):
            recover(old.with_name(old.name[1:-4]))
        return gait_order(
            p.name
            for p in self.root.iterdir()
            if not p.name.startswith(".") and p.name != self.SWITCHING and (p / "metadata.json").is_file()
        )

    def order(self, names: Iterable[str] | None = None) -> tuple[str, ...]:
        """``names`` (``None``: every entry) checked to be entries of this library, in canonical order;
        :class:`LibraryError` names the first that is not."""
        if names is None:
            return self.gaits()
        names = [str(n).strip() for n in names]
        known = self.gaits()
        for name in names:
            if name not in known:
                raise LibraryError(
                    f"no library entry for gait '{name}' in {self.root} (entries: {', '.join(known) or 'none'})"
                )
        return gait_order(names)

    def entry(self, name: str) -> LibraryEntry:
        """The loaded entry of gait ``name`` (loaded and checked on first use); :class:`LibraryError` if it is
        missing or damaged."""
        if name not in self._entries:
            self.order([name])  # one refusal, naming the entries there are, for a gait the library lacks
            self._entries[name] = _load_entry(self.root, name)
        return self._entries[name]

    def entries(self, names: Iterable[str] | None = None) -> list[LibraryEntry]:
        """The entries of ``names`` (``None``: all), in canonical order."""
        return [self.entry(name) for name in self.order(names)]

    def identities(self, names: Iterable[str] | None = None) -> dict[str, str]:
        """Gait name -> identity (SHA-256 of the weights) of ``names`` (``None``: all), in canonical order."""
        return {e.name: e.identity for e in self.entries(names)}

    def check_identities(self, recorded: Mapping[str, str], *, what: str) -> None:
        """Refuse a file made for other policies than this library's (see :func:`check_identities`)."""
        known = self.gaits()
        check_identities(recorded, self.identities(g for g in recorded if g in known), what=what)

    def shared_policy_settings(self, names: Iterable[str] | None = None) -> PolicySettings:
        """The latent size, action settings, observation options and action delay that the entries of ``names``
        share: policies that drive one environment and fill one transition file must agree on them."""
        entries = self.entries(names)
        if not entries:
            where = "has no gait entries" if self.root.is_dir() else "does not exist"
            raise LibraryError(f"library {self.root} {where}; train a gait into it first: gaitlib train GAIT "
                               f"--library {self.root}")
        checks = {
            "latent sizes": {e.name: e.policy.latent_dim for e in entries},
            "action settings": {e.name: (e.action["type"], e.action_scale, e.action_clip) for e in entries},
            "observations": {e.name: e.observation for e in entries},
            "action delays": {e.name: e.action_delay_steps for e in entries},
        }
        for what, values in checks.items():
            if len(set(values.values())) != 1:
                raise LibraryError(f"library policies have different {what} {values}; {self._retrain_alike(values)}")
        first = entries[0]
        return PolicySettings(
            latent_dim=first.policy.latent_dim,
            action={"type": first.action["type"], "scale": first.action_scale, "clip": first.action_clip},
            observation=first.observation,
            action_delay_steps=first.action_delay_steps,
        )

    def _retrain_alike(self, values: Mapping[str, object]) -> str:
        """The commands that retrain the gaits whose value differs from the most common one, with the preset of a
        gait that has it."""
        counts = {value: list(values.values()).count(value) for value in values.values()}
        common = max(counts, key=lambda value: counts[value])
        model = next(name for name, value in values.items() if value == common)
        preset = self.entry(model).metadata.get("training", {}).get("preset", {}).get("name", "cpu")
        odd = [name for name, value in values.items() if value != common]
        return "retrain them like " + model + ": " + " && ".join(
            f"gaitlib train {name} --preset {preset} --library {self.root}" for name in odd
        )

    def save_entry(
        self,
        *,
        description: GaitDescription,
        actor: torch.nn.Module,
        critic: torch.nn.Module,
        networks: dict,
        action: dict,
        observation: obs_fn.ObservationConfig,
        training: dict,
        evaluation: dict,
    ) -> Path:
        """Write ``<root>/<gait>/`` atomically (into a temporary folder, then renamed over the old entry).

        ``networks``: ``actor_hidden``, ``critic_hidden``, ``activation``; ``action``: ``type``, ``scale``, ``clip``;
        ``observation``: the options of the observations the policy was trained on;
        ``training`` and ``evaluation``: free-form records of how the policy was made and how good it is.
        """
        self._entries.pop(description.name, None)
        with staged_folder(self.root / description.name) as staging:
            weights = staging / "policy.pt"
            weights.write_bytes(torch_bytes({"actor": actor.state_dict(), "critic": critic.state_dict()}))
            export_onnx(actor, staging / "policy.onnx")
            metadata = {
                "format_version": FORMAT_VERSION,
                "gait": description.name,
                "description": description.record(),
                "robot": "a1",
                "observation": obs_fn.layout(observation),
                "action": action,
                "networks": networks,
                "training": training,
                "evaluation": evaluation,
                "versions": _versions(),
                "sha256": file_sha256(weights),
                "onnx_sha256": file_sha256(staging / "policy.onnx"),
                "deployment": deployment_block(
                    clip=clip_from_description(description),
                    action=action,
                    observation=observation,
                    onnx_path=staging / "policy.onnx",
                    action_delay_steps=tuple(training.get("randomization", {}).get("action_delay_steps", (0, 0))),
                ),
            }
            write_json(staging / "metadata.json", metadata, checksum=True)
        return self.root / description.name

    def record_evaluation(self, name: str, evaluation: dict) -> Path:
        """Make ``evaluation`` the stored evaluation of entry ``name`` (its ``metadata.json``; the weights and
        everything else untouched), published like a new entry: a reader sees the old or the new folder whole."""
        entry = self.entry(name)  # a missing or damaged entry: one line, before anything is written
        metadata = {k: v for k, v in entry.metadata.items() if k != CHECKSUM_KEY} | {"evaluation": evaluation}
        self._entries.pop(name, None)
        folder = self.root / name
        with staged_folder(folder) as staging:
            for item in folder.iterdir():
                if item.is_file() and item.name != "metadata.json":
                    shutil.copy2(item, staging / item.name)
            write_json(staging / "metadata.json", metadata, checksum=True)
        return folder


def _load_entry(library: Path, name: str) -> LibraryEntry:
    """Load and check the entry ``library/<name>/`` (which exists); raises :class:`LibraryError` with a one-line
    reason."""
    folder = library / name
    meta_path = folder / "metadata.json"
    try:
        metadata = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise LibraryError(f"library entry '{name}' has unreadable metadata: {error}") from error
    if isinstance(metadata, dict) and metadata.get(CHECKSUM_KEY) != json_checksum(metadata):
        raise LibraryError(
            f"library entry '{name}' is damaged: metadata.json does not match its checksum (changed after it was "
            "written)"
        )
    if not isinstance(metadata, dict) or metadata.get("format_version") != FORMAT_VERSION:
        version = metadata.get("format_version") if isinstance(metadata, dict) else None
        raise LibraryError(
            f"library entry '{name}' has format version {version}, this gaitlib reads version {FORMAT_VERSION}; "
            "retrain it with this gaitlib"
        )
    observation = obs_fn.observation_config(metadata.get("observation"))
    if observation is None or json.dumps(metadata["observation"]) != json.dumps(obs_fn.layout(observation)):
        raise LibraryError(f"library entry '{name}' was trained with another observation layout (metadata field "
                           f"observation, {meta_path}); retrain it with this gaitlib")
    try:
        check_action(metadata.get("action"))
        check_metadata(metadata)
    except Invalid as refused:
        raise LibraryError(f"library entry '{name}' has damaged metadata: {refused} ({meta_path})") from None
    named = {metadata["gait"], metadata["description"]["name"]}
    if named != {name}:
        raise LibraryError(
            f"library entry '{name}' holds gait {sorted(map(str, named - {name}))} by its metadata; an entry's folder "
            "is named after its gait (a policy copied into another gait's folder?)"
        )
    weights = folder / "policy.pt"
    if not weights.is_file() or file_sha256(weights) != metadata.get("sha256"):
        raise LibraryError(f"library entry '{name}' is damaged: policy.pt is missing or does not match its checksum")
    onnx = folder / "policy.onnx"  # the file a user deploys: checked where the entry records its checksum
    if "onnx_sha256" in metadata and (
        not onnx.is_file() or file_sha256(onnx) != metadata["onnx_sha256"]
    ):
        raise LibraryError(f"library entry '{name}' is damaged: policy.onnx is missing or does not match its checksum")
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
        description = GaitDescription(**metadata["description"])
        nets = metadata["networks"]
        policy = GaitPolicy.from_state(
            state,
            actor_hidden=tuple(nets["actor_hidden"]),
            critic_hidden=tuple(nets["critic_hidden"]),
            activation=nets["activation"],
            num_actions=get_robot(metadata.get("robot", "a1")).num_joints,
            observation=observation,
        )
        clip = clip_from_description(description)
    except (KeyError, TypeError, RuntimeError, ValueError, GaitlibError) as error:
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise LibraryError(f"library entry '{name}' cannot be loaded: {first}") from error
    entry = LibraryEntry(name=name, metadata=metadata, policy=policy, description=description,
                         clip=clip)
    try:
        check_deployment(metadata, entry.clip, observation, entry.action_delay_steps, onnx)
    except Invalid as refused:
        raise LibraryError(f"library entry '{name}' has damaged metadata: {refused} ({meta_path})") from None
    return entry


def _versions() -> dict[str, str]:
    from importlib.metadata import version

    import gaitlib

    return {
        "gaitlib": gaitlib.__version__,
        "torch": torch.__version__,
        "rsl-rl-lib": version("rsl-rl-lib"),
        "mujoco": version("mujoco"),
    }

