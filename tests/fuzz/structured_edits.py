"""Structured edits for tests/fuzz/byte_flips.py (``--edits N``; the command, its output and its exit status are
described there): wrong content put into a file gaitlib reads, the file kept parseable and its checksum valid.

A structured edit loads a file as data, changes it in place and writes it back with its checksum recomputed, so that
only a check of the content itself can tell: a wrong type, a value out of range, a missing key, extra nesting, a nan
or an infinity as Python's json writes them, a count above its total, a zero quaternion, a wrong-width array, swapped
gait names, ... Each kind of file (:class:`EditTarget`, made by :func:`edit_targets`) has edits of its meaning written
for it and controls that change nothing read; :data:`GENERIC` edits apply to any field. :func:`edit` applies them one
at a time, reads the file as its command does, and counts what happened.
"""

from __future__ import annotations

import dataclasses
import json
import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import CHECKSUM_KEY, json_checksum
from gaitlib.benchmark.report import cell_results
from gaitlib.benchmark.results import load_results, open_results
from gaitlib.envs.handover import load_states
from gaitlib.envs.observations import ObservationBatch
from gaitlib.errors import GaitlibError
from gaitlib.library import Library
from gaitlib.strategies.routes import load_routes
from gaitlib.training.switch_start import handover_states

__all__ = ["GENERIC", "EditTarget", "edit", "edit_targets"]

@dataclass
class EditTarget:
    """One kind of file for structured edits: its path, how it is read and written as data (its checksum
    recomputed), what its command takes from it, the keys its format requires and edits of its meaning."""

    path: Path
    load: Callable[[Path], dict]
    save: Callable[[Path, dict], None]
    read: Callable[[], object]
    required: tuple[str, ...]
    """Key paths (``*`` for any one key) a file of the format always holds: deleting one is wrong content."""
    semantic: dict[str, Callable[[dict], None]]
    """Edits of meaning, each in place on the loaded content: label -> edit."""
    json_root: tuple[str, ...] = ()
    """Where the JSON content lies in the loaded data (``("meta",)`` for the states file)."""


def _load_json(path: Path) -> dict:
    return json.loads(path.read_text())


def _save_json(path: Path, payload: dict) -> None:
    """``payload`` with a matching checksum, nan and infinities as Python's json writes them (another writer)."""
    body = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    path.write_text(json.dumps(body | {CHECKSUM_KEY: json_checksum(body)}))


def _load_npz(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as npz:
        return {"meta": json.loads(str(npz["meta"])), "arrays": {k: npz[k] for k in npz.files if k != "meta"}}


def _save_npz(path: Path, content: dict) -> None:
    with open(path, "wb") as handle:
        np.savez(handle, meta=np.array(json.dumps(content["meta"])), **content["arrays"])


_HEADER = ("format", "format_version", CHECKSUM_KEY)


def _nodes(value: object, where: tuple = ()) -> list[tuple[tuple, object]]:
    """Every node under ``value`` (its key path and value), the header keys left out."""
    found = []
    children = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, child in children:
        if not where and key in _HEADER:
            continue
        found += [((*where, key), child), *_nodes(child, (*where, key))]
    return found


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


GENERIC = {  # label -> (applies to, the wrong value)
    "a string for a number": (lambda v: _is_number(v) or v is None, lambda v: json.dumps(v)),
    "a number for a string": (lambda v: isinstance(v, str), lambda v: 7),
    "a number for true/false": (lambda v: isinstance(v, bool), lambda v: int(v)),
    "true for a number": (_is_number, lambda v: True),
    "an object for a list": (lambda v: isinstance(v, list), lambda v: {str(i): x for i, x in enumerate(v)}),
    "a list for an object": (lambda v: isinstance(v, dict), lambda v: list(v.values())),
    "nan": (_is_number, lambda v: float("nan")),
    "Infinity": (_is_number, lambda v: float("inf")),
    "-Infinity": (_is_number, lambda v: float("-inf")),
    "extra nesting in a list": (lambda v: True, lambda v: [v]),
    "extra nesting in an object": (lambda v: True, lambda v: {"value": v}),
    "a missing key": (lambda v: True, None),
}
"""Edits wrong for any field of gaitlib's JSON files (every number finite, every field of one type)."""


def _matches(pattern: str, where: tuple) -> bool:
    parts = pattern.split(".")
    return len(parts) == len(where) and all(p in ("*", str(k)) for p, k in zip(parts, where, strict=True))


def _generic_edit(target: EditTarget, content: dict, rng: random.Random) -> str | None:
    """One generic edit of ``content`` in place at a random node (a section of the file drawn first, so that a big
    one, the deployment block, does not take every edit); its label, or ``None`` if the drawn edit applies nowhere."""
    label = rng.choice(list(GENERIC))
    applies, wrong = GENERIC[label]
    root = content
    for key in target.json_root:
        root = root[key]
    section = rng.choice([k for k in root if k not in _HEADER])
    nodes = [(w, v) for w, v in _nodes(root) if w[0] == section and applies(v)
             and (wrong is not None or any(_matches(p, w) for p in target.required))]
    if not nodes:
        return None
    where, value = rng.choice(nodes)
    parent = root
    for key in where[:-1]:
        parent = parent[key]
    if wrong is None:
        del parent[where[-1]]
    else:
        parent[where[-1]] = wrong(value)
    return f"{label} at {'.'.join(map(str, where))}"


def edit(target: EditTarget, count: int, rng: random.Random, same: Callable[[object, object], bool]) -> dict:
    """``count`` structured edits of ``target``'s file, one at a time, the file restored after each: about half
    its edits of meaning (all of them when ``count`` is twice their number or more), the rest generic; the
    outcomes counted (``same`` telling a harmless result from a wrong one), the harmless and the bad ones named."""
    pristine, expected = target.path.read_bytes(), target.read()
    semantic = list(target.semantic)
    rng.shuffle(semantic)
    semantic = semantic[: min(len(semantic), (count + 1) // 2)]
    counts = {"count": count, "refused": 0, "harmless": 0, "wrong": 0, "crashed": 0}
    named: dict[str, list[str]] = {"harmless_edits": [], "bad_edits": []}
    try:
        for i in range(count):
            target.path.write_bytes(pristine)
            content = target.load(target.path)
            if i < len(semantic):
                label = semantic[i]
                target.semantic[label](content)
            else:
                label = None
                while label is None:
                    label = _generic_edit(target, content, rng)
            target.save(target.path, content)
            try:
                got = target.read()
            except GaitlibError as error:
                one_line = "\n" not in str(error)
                counts["refused" if one_line else "crashed"] += 1
                if not one_line:
                    named["bad_edits"].append(f"{label}: refused in several lines")
                continue
            except Exception as error:  # a traceback instead of one line
                counts["crashed"] += 1
                named["bad_edits"].append(f"{label}: {type(error).__name__}: {error}"[:200])
                continue
            if same(got, expected):
                counts["harmless"] += 1
                named["harmless_edits"].append(label)
            else:
                counts["wrong"] += 1
                named["bad_edits"].append(f"{label}: accepted with a different result")
    finally:
        target.path.write_bytes(pristine)
    return {"file": target.path.name, **counts, **named}


def _at(where: str, value: object) -> Callable[[dict], None]:
    """An edit setting the key path ``where`` (``.``-separated; ``^`` the first key of an object, a number a list
    index, ``+`` a new last item) to ``value``, or to ``value(old)`` if it is callable."""

    def change(content: dict) -> None:
        *parents, last = where.split(".")
        node = content
        for key in parents:
            node = node[_key(node, key)]
        if last == "+":
            node.append(value)
            return
        key = _key(node, last)
        node[key] = value(node[key]) if callable(value) else value

    return change


def _key(node: object, key: str) -> object:
    return next(iter(node)) if key == "^" else int(key) if isinstance(node, list) else key


def _call(method: str, where: str, *args: object) -> Callable[[dict], None]:
    """An edit calling ``method(*args)`` on the object at the key path ``where`` (``""``: the whole content)."""

    def change(content: dict) -> None:
        node = content
        for key in filter(None, where.split(".")):
            node = node[_key(node, key)]
        getattr(node, method)(*args)

    return change


def _reorder(mapping: dict) -> None:
    """The same content, its keys written in another order: harmless."""
    items = list(mapping.items())[::-1]
    mapping.clear()
    mapping.update(items)


def _swap_first_two(mapping: dict) -> None:
    a, b = list(mapping)[:2]
    mapping[a], mapping[b] = mapping[b], mapping[a]


def edit_targets(root: Path, gaits: tuple[str, ...]) -> dict[str, EditTarget]:
    """The four kinds of file of structured edits, in the folder byte_flips.py's ``build`` made of ``gaits``, each
    read as its command reads it: a routed run, a resumed benchmark and its report, ``gaitlib train --states``, an
    entry's policy."""
    library, out, states = root / "library", root / "bench", root / "states.npz"
    results = _load_json(out / "results.json")
    settings, identities = results["settings"], results["library_identities"]
    cell = "groups.^.cells.^"
    samples = results["settings"]["samples"]

    def routes() -> object:
        table = load_routes(Library(library), gaits)
        return dataclasses.asdict(table), table.detours(), table.expand("stand", ("trot", "stand"))

    def benchmark() -> object:
        loaded = load_results(out)
        return loaded, open_results(out, settings, identities), [dataclasses.asdict(r) for r in cell_results(loaded)]

    def handover() -> object:
        loaded, sha256 = load_states(states)
        return dataclasses.asdict(loaded), sha256, handover_states(states, 0.5, gait="stand")[1]

    def entry() -> object:
        loaded = Library(library).entry("stand")
        probe = ObservationBatch(policy=torch.linspace(-1, 1, 159).unsqueeze(0), privileged=torch.zeros(1, 14))
        return loaded.metadata, loaded.policy.act(probe).numpy(), loaded.action_delay_steps, loaded.description

    def arrays(name: str, index: object, value: object) -> Callable[[dict], None]:
        return lambda c: c["arrays"][name].__setitem__(index, value)

    def reshape(name: str, change: Callable[[np.ndarray], np.ndarray]) -> Callable[[dict], None]:
        return lambda c: c["arrays"].__setitem__(name, change(c["arrays"][name]))

    return {
        "route table": EditTarget(
            path=library / "switching" / "routes.json", load=_load_json, save=_save_json, read=routes,
            required=("gaits", "strategy", "push_n", "max_legs", "rates", "policies", "switching", "measured_with",
                      "rates.*", "policies.*", "measured_with.*"),
            semantic={
                "a success count above its total": _at("rates.^", lambda r: [r[1] + 1, r[1]]),
                "a negative success count": _at("rates.^.0", -1),
                "a fractional count": _at("rates.^.0", lambda n: n + 0.5),
                "a total other than the samples measured": _at("rates.^.1", lambda n: n + 7),
                "a zero total": _at("rates.^", [0, 0]),
                "three numbers for a rate": _at("rates.^.+", 1),
                "a negative push": _at("push_n", -50.0),
                "a push beyond 2000 N": _at("push_n", 1e6),
                "an unknown strategy": _at("strategy", "teleport"),
                "an unknown gait": _at("gaits.1", "zebra"),
                "swapped gait names": _call("reverse", "gaits"),
                "a gait listed twice": _at("gaits", lambda g: [g[0], g[0]]),
                "swapped identities": lambda c: _swap_first_two(c["policies"]),
                "a pair of one gait": _at("rates.stand-stand", [1, 2]),
                "a pair of an unknown gait": _at("rates.stand-zebra", [1, 2]),
                "a pair missing": _call("pop", "rates", "stand-trot"),
                "no switch in a route": _at("max_legs", 0),
                "a route of a million switches": _at("max_legs", 10**6),
                "an unknown definition of a fall": _at("measured_with.falls", "sometimes"),
                "a horizon shorter than the deadline": _at("measured_with.horizon_s", 0.01),
                "no samples": _at("measured_with.samples", 0),
                "a detour the rates do not give": _at("detours", {"stand-trot": ["stand", "trot", "stand"]}),
                "a switching identity that is no SHA-256": _at("switching", "abc"),
                "(the keys in another order)": _reorder,
                "(the derived detours left out)": _call("pop", "", "detours"),
            },
        ),
        "handover states": EditTarget(
            path=states, load=_load_npz, save=_save_npz, read=handover, json_root=("meta",),
            required=("gaits", "identities", "settings", "identities.*", "settings.per_gait", "settings.push_max",
                      "settings.num_worlds", "settings.warmup_s", "settings.spacing_s", "settings.backend",
                      "settings.seed"),
            semantic={
                "a zero quaternion": arrays("root_quat", 0, 0.0),
                "a quaternion of norm 2": arrays("root_quat", 0, [2.0, 0.0, 0.0, 0.0]),
                "a trunk at 50 m": arrays("root_height", 0, 50.0),
                "a trunk below the ground": arrays("root_height", 0, -0.1),
                "frames of the wrong width": reshape("history", lambda a: a[..., :-1]),
                "a last reading of the wrong width": reshape("last_reading", lambda a: np.pad(a, ((0, 0), (0, 1)))),
                "joints of the wrong width": reshape("joint_pos", lambda a: a[:, :11]),
                "a nan joint velocity": arrays("joint_vel", (0, 0), np.nan),
                "an infinite trunk velocity": arrays("root_lin_vel", (0, 0), np.inf),
                "a trunk at 1e6 m/s": arrays("root_lin_vel", (0, 0), 1e6),
                "a phase of 1.5 cycles": arrays("phase", 0, 1.5),
                "a PD target 10 rad away": arrays("targets", (0, 0, 0), 10.0),
                "a gait index out of range": arrays("source", 0, 5),
                "a negative gait index": arrays("source", 0, -1),
                "gait indices as floats": reshape("source", lambda a: a.astype(float)),
                "frames as integers": reshape("history", lambda a: a.astype(np.int64)),
                "a missing array": _call("pop", "arrays", "targets"),
                "an array too many": _at("arrays.extra", np.zeros(3)),
                "arrays of different lengths": reshape("action", lambda a: a[:-1]),
                "an empty delay line": reshape("targets", lambda a: a[:, :0]),
                "a phase per state as a column": reshape("phase", lambda a: a[:, None]),
                "swapped gait names": _call("reverse", "meta.gaits"),
                "a gait listed twice": _at("meta.gaits", lambda g: [g[0], g[0]]),
                "no gaits": _at("meta.gaits", []),
                "an identity missing": _call("pop", "meta.identities", "stand"),
                "an identity of an unknown gait": _at("meta.identities.zebra", "0" * 64),
                "a negative push": _at("meta.settings.push_max", -1.0),
                "no spacing between states": _at("meta.settings.spacing_s", 0.0),
                "an unknown backend": _at("meta.settings.backend", "quantum"),
            },
        ),
        "entry metadata.json": EditTarget(
            path=library / "stand" / "metadata.json", load=_load_json, save=_save_json, read=entry,
            required=("gait", "description", "robot", "observation", "action", "networks", "training", "evaluation",
                      "versions", "sha256", "deployment", "description.name", "description.phase_offsets",
                      "description.duty_factor", "description.stride_frequency", "description.forward_speed",
                      "description.swing_height", "description.body_height", "action.*", "networks.*",
                      "versions.*", "deployment.*", "deployment.*.*", "training.curve.*", "training.preset.name",
                      *(f"training.{k}" for k in ("preset", "backend", "iterations", "samples", "wall_clock_s",
                                                  "seed", "randomization", "episode_seconds", "curve")),
                      *(f"evaluation.{k}" for k in ("episodes", "seconds", "fall_rate", "fall_ci95", "touch_rate",
                                                    "falls", "falls_by_cause", "push_max", "mean_episode_seconds"))),
            semantic={
                "a fall rate above 1": _at("evaluation.fall_rate", 1.5),
                "a negative fall rate": _at("evaluation.fall_rate", -0.1),
                "no episodes": _at("evaluation.episodes", 0),
                "a fall rate outside its interval": _at("evaluation.fall_ci95", [0.5, 0.6]),
                "a fall rate that is no count": _at("evaluation.fall_rate", 0.3),
                "falls of a cause above the episodes": _at("evaluation.falls_by_cause.too_low", 99),
                "a touch longer than an episode": _at("evaluation.longest_touch_s", 1e4),
                "an unknown definition of a fall": _at("evaluation.falls", "sometimes"),
                "another gait's name": _at("gait", "trot"),
                "another gait's description": _at("description.name", "trot"),
                "a duty factor of 0": _at("description.duty_factor", 0.0),
                "a trunk at 50 m": _at("description.body_height", 50.0),
                "a negative stride frequency": _at("description.stride_frequency", -2.0),
                "a phase offset of 1.5": _at("description.phase_offsets.0", 1.5),
                "five phase offsets": _at("description.phase_offsets.+", 0.0),
                "a changed forward speed": _at("description.forward_speed", 0.3),
                "an unknown robot": _at("robot", "spot"),
                "an action scale of 0": _at("action.scale", 0.0),
                "a changed action scale": _at("action.scale", lambda x: 2 * x),
                "networks not the preset's": _at("networks.activation", "tanh"),
                "a curve row of another width": _at("training.curve.rows.0.+", 1.0),
                "an unknown backend": _at("training.backend", "quantum"),
                "a delay range upside down": _at("training.randomization.action_delay_steps", [1, 0]),
                "a changed trained delay": _at("training.randomization.action_delay_steps", [0, 3]),
                "a negative observation noise": _at("training.randomization.observation_noise", -0.1),
                "a weights checksum that is no SHA-256": _at("sha256", "abc"),
                "another stiffness in the deployment block": _at("deployment.control.kp", 61.0),
                "joint names swapped in the deployment block": _call("reverse", "deployment.robot.joint_names"),
                "a version that is a number": _at("versions.torch", 2.13),
                "(the keys in another order)": _reorder,
            },
        ),
        "benchmark results.json": EditTarget(
            path=out / "results.json", load=_load_json, save=_save_json, read=benchmark,
            required=("settings", "library_identities", "groups", "settings.strategies", "settings.magnitudes",
                      "settings.samples", "settings.pairs", "settings.num_worlds", "settings.seed", "settings.falls",
                      "settings.warmup_s", "settings.horizon_s", "settings.deadline_s", "library_identities.*",
                      "groups.*.*", "groups.*.cells.*", "groups.*.cells.*.*"),
            semantic={
                "a success count above its samples": _at(f"{cell}.successes", samples + 1),
                "a negative touch count": _at(f"{cell}.touched", -1),
                "samples other than the settings'": _at(f"{cell}.samples", samples + 1),
                "more forced switches than switches": _at(f"{cell}.forced", lambda n: n + samples + 1),
                "more switches than transitions": _at(f"{cell}.switched", samples + 1),
                "a wait beyond the deadline": _at(f"{cell}.wait_s", 1e4),
                "a touch longer than a transition is watched": _at(f"{cell}.longest_touch_s", 1e4),
                "touches without a longest touch": _at(cell, lambda c: c | {"touched": 1, "longest_touch_s": 0.0}),
                "a fractional count": _at(f"{cell}.successes", 0.5),
                "an unknown strategy in a group": _at("groups.^.strategy", "teleport"),
                "a group under another key": _at("groups.^.magnitude_n", 50.0),
                "an unknown backend": _at("groups.^.backend", "quantum"),
                "a negative elapsed time": _at("groups.^.elapsed_s", -1.0),
                "a magnitude beyond 2000 N": _at("settings.magnitudes", [5000.0]),
                "a negative magnitude": _at("settings.magnitudes", [-50.0]),
                "an unknown strategy in the settings": _at("settings.strategies", ["teleport"]),
                "a pair of an unknown gait": _at("settings.pairs.0.1", "zebra"),
                "a pair of one gait": _at("settings.pairs.0", lambda p: [p[0], p[0]]),
                "swapped pair": _call("reverse", "settings.pairs.0"),
                "swapped cell names": _at("groups.^.cells", lambda cells: {
                    "-".join(reversed(k.split("-"))): v for k, v in cells.items()}),
                "swapped identities": lambda c: _swap_first_two(c["library_identities"]),
                "no samples": _at("settings.samples", 0),
                "an unknown definition of a fall": _at("settings.falls", "sometimes"),
                "a route of an unmeasured pair": _at("settings.routes", {"stand-zebra": ["stand", "zebra"]}),
                "an identity that is no SHA-256": _at("library_identities.stand", "abc"),
                "(the keys in another order)": _reorder,
            },
        ),
    }
