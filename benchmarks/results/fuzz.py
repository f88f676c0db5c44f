"""The generated tables of ``docs/failures.md``, "Damaged or foreign files": what ``tests/fuzz/byte_flips.py`` counted
when it flipped bytes of each kind of file gaitlib reads (:func:`flips_table`) and when it put wrong content into them
with their checksums kept valid (:func:`edits_table`).

The script prints one JSON line a kind of file; their list is stored as the evidence ``docs/results/fuzz/NAME.json``
(``command``, ``made``, ``result``). What each kind's check is (the descriptive columns) is written here, by the kind's
name as the script prints it; every count is read from the evidence, and a kind the script prints that is not
described here is refused in one line.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import ROOT, cite, not_yet, read_evidence

__all__ = ["EDITED", "EDITS", "FLIPPED", "FLIPS", "FUZZ", "edits_table", "flips_table"]

FUZZ = ROOT / "docs" / "results" / "fuzz"
"""Where the fuzz runs' evidence is stored."""
FLIPS = FUZZ / "byte-flips.json"
"""The byte flips: ``python tests/fuzz/byte_flips.py --flips 100``."""
EDITS = FUZZ / "edits.json"
"""The structured edits: ``python tests/fuzz/byte_flips.py --flips 0 --edits 100``."""

_SWITCHING = "`switching/checksums.json` (SHA-256 of each), identities against the library, finite numbers"
_INDEX = ("`index_sha256` over its attributes and part list; HDF5's own structure",
          "changed settings, gaits, identities, counts, sessions, part list", "flips in bytes HDF5 does not use")
FLIPPED = {
    "entry metadata.json": ("`GAIT/metadata.json`", "its own `checksum` (SHA-256 of the rest, canonical JSON), then "
                            "format, action settings, gait name against the folder",
                            "any changed value; a policy copied into another gait's folder",
                            "a file rewritten whole, checksum recomputed (a deliberate edit: its content is checked "
                            "by schema, below)"),
    "entry policy.pt": ("`GAIT/policy.pt`", "`sha256` in the metadata (the entry's identity)", "any changed byte",
                        "a new policy with new metadata (then it is another identity)"),
    "entry policy.onnx": ("`GAIT/policy.onnx`", "`onnx_sha256` in the metadata (entries written from 0.2.0 on)",
                          "any changed byte, a truncated or foreign file",
                          "entries of earlier versions, which record no ONNX checksum"),
    "switching net.pt": ("`switching/net.pt`", _SWITCHING, "any changed byte (torch itself accepts most flipped bits "
                         "of a checkpoint: 138 of 200 in a test)", "a whole fit replaced consistently"),
    **{f"switching {name}": (f"`switching/{name}`", f"{_SWITCHING}, its own checksum", "any changed byte",
                             "a whole fit replaced consistently")
       for name in ("tmt.json", "calibration.json", "accuracy.json")},
    "switching checksums.json": ("`switching/checksums.json`", "its own checksum", "any changed value", ""),
    "switching survival.pt": ("`switching/survival.pt` (the guard's estimate)", "its SHA-256 in "
                              "`switching/checksums.json`, then format, finite weights, Platt parameters, horizon, "
                              "margin and floor, identities against the library", "any changed byte, a truncated file",
                              "an estimate rewritten whole with its checksum listed anew (then checked for finite "
                              "numbers and identities)"),
    "transition index": ("transition index (`t.h5`)", *_INDEX),
    "transition part": ("transition part", "its SHA-256 in the index (and Fletcher-32 per chunk)", "any changed byte",
                        ""),
    "benchmark results.json": ("benchmark `results.json`", "its own checksum, format, settings and identities "
                               "against the run", "any changed value", ""),
    "handover states": ("handover states (`.npz`)", "the zip's CRC-32 of each array, format, finite values, gait "
                        "indices", "any changed array byte", "flips in zip bytes nothing reads"),
    "resume: its gait file": ("resume identity: the gait file a run was started from, then `train --resume`",
                              "the checkpoint's record of the description's content, field by field",
                              "any changed value of the description",
                              "flips in comments and spaces (the description read is the same, so the resume goes on)"),
    "resume: its states file": ("resume identity: the `--states` file, then `train --resume`",
                                "the checkpoint's SHA-256 of the file's bytes",
                                "any changed byte, whether or not a reader uses it", ""),
    "data overlap: a copy's index": ("data overlap: a copy's index, fitted on beside the original",
                                     "as the transition index; the same content read once", "as the transition index",
                                     "flips in bytes HDF5 does not use (the copy then counted once)"),
    "data overlap: a copy's part": ("data overlap: a copy's part, fitted on beside the original",
                                    "as the transition part", "any changed byte", ""),
}
"""Each flipped kind of file, by the script's name of it: the file as the page names it, what checks it, what the
check catches and what it cannot catch."""
EDITED = {
    "route table": ("`switching/routes.json`", "`load_routes` (`run --routed`, `benchmark --routed`, `library`)",
                    "every ordered pair of its gaits (sorted, each once), no other; successes within transitions, as "
                    "many transitions as measured; a known strategy; push in [0, 2000] N; route length, protocol "
                    "times, definition of a fall; the detours its rates give; policies and switching models against "
                    "the library"),
    "handover states": ("handover states (`.npz`)", "`load_states` (`train --states`)",
                        "every array present, no other, of S states, frames of 34 values, 12 joints, a delay line of "
                        "1 to 32 targets; floating-point, finite, in physical ranges (trunk in (0, 2] m, joints within "
                        "a turn, speeds); unit quaternions (to 1e-3); gait indices of the listed gaits; gaits sorted, "
                        "each once, an identity each; recording settings"),
    "entry metadata.json": ("`GAIT/metadata.json`", "`Library.entry` (every command)",
                            "description (ranges, then the gait's own checks), robot, networks (as the preset's), "
                            "training record (preset, randomization ranges, learning curve, recipe, switch-start "
                            "record), evaluation (rates in [0, 1] inside their intervals and counts of the episodes, "
                            "the figures of one record together), versions, checksums; the `deployment` block equal "
                            "to the one the entry's own settings and `policy.onnx` give"),
    "benchmark results.json": ("benchmark `results.json`", "`load_results` (a resumed `benchmark`, `routes`)",
                               "settings (known strategies, magnitudes in [0, 2000] N, pairs and routes of the "
                               "measured gaits); each group under its own key, of a strategy and magnitude the "
                               "settings name, with a cell of each pair; each cell of the settings' samples, "
                               "successes, touches and switches within them, forced switches within switches, waits "
                               "within the deadline, a longest touch where touches are and within the time watched"),
    "resume identity": ("resume identity: the gait file a run was started from",
                        "`resume_point` (`train --resume`), before any simulation",
                        "the description's every field against the checkpoint's record (another body height, stride, "
                        "duty factor, swing, phase, name, stance, sway or bounce), then the gait file's own checks "
                        "(types, ranges, keys)"),
    "data overlap": ("data overlap: the file's samples given to a fit a second time", "`read_all` (`fit`, "
                     "`fit --evaluate`)", "each file's content SHA-256 (the same path twice, a hard or symbolic link, "
                     "a copy, a copy with its index written again) and each sample's bytes (half its samples in a new "
                     "file, its samples in another order, a collection with the same seed and settings): counted "
                     "once, the note naming the file and why"),
}
"""Each edited kind of file, by the script's name of it: the file as the page names it, its reader (and the commands
that use it) and what the reader checks."""


def _described(kind: str, described: dict[str, tuple[str, ...]], path: Path) -> tuple[str, ...]:
    if kind not in described:
        raise ValueError(f"{path} holds the kind '{kind}', which benchmarks/results/fuzz.py does not describe")
    return described[kind]


def flips_table(path: Path = FLIPS) -> str:
    """Each kind of file: its check, what it catches and cannot, and the flips refused, read the same, read
    differently and crashed (a traceback), as the stored run counted them."""
    evidence = read_evidence(Path(path))
    if evidence is None:
        return not_yet(Path(path))
    lines = evidence["result"]
    flips = sorted({line["flips"] for line in lines})
    rows = ["| file | checked by | catches | cannot catch | flips: refused / same / different / crashed |",
            "|---|---|---|---|---|"]
    for line in lines:
        shown, checked, catches, cannot = _described(line["file"], FLIPPED, Path(path))
        counts = " / ".join(str(line[key]) for key in ("refused", "same", "different", "crashed"))
        rows.append(f"| {shown} | {checked} | {catches} | {cannot} | {line['flips']}: {counts} |")
    bad = [line["file"] for line in lines if line["different"] or line["crashed"]]
    found = (f"Read differently or crashed: {', '.join(bad)}; the script exits non-zero for it." if bad else
             "No flip was read differently and none crashed.")
    return "\n".join([*rows, "", f"{' or '.join(map(str, flips))} flips a kind. {found} Evidence: "
                      f"{cite(Path(path), evidence)}."])


def edits_table(path: Path = EDITS) -> str:
    """Each kind of file edited with its checksum kept valid: its reader, what it checks, and the edits refused,
    harmless (which ones), read wrong and crashed, as the stored run counted them."""
    evidence = read_evidence(Path(path))
    if evidence is None:
        return not_yet(Path(path))
    rows = ["| file | read by | checked | edits | refused in one line | harmless | wrong result | traceback |",
            "|---|---|---|---|---|---|---|---|"]
    for line in evidence["result"]:
        shown, reader, checked = _described(line["edits"], EDITED, Path(path))
        harmless = ", ".join(sorted({name.strip("()") for name in line["harmless_edits"]}))
        rows.append(f"| {shown} | {reader} | {checked} | {line['count']} | {line['refused']} | {line['harmless']}"
                    f"{f' ({harmless})' if harmless else ''} | {line['wrong']} | {line['crashed']} |")
    return "\n".join([*rows, "", f"Evidence: {cite(Path(path), evidence)}."])
