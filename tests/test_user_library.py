"""The shipped library is never clobbered: training writes into the user's own library by default, replaces a
shipped entry only with --replace, keeps the tests' preset out of trained libraries; ``gaitlib library`` names
what is stale with the commands that fix it, and those commands do fix it."""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import gaitlib_quick
from conftest import copy_library, git

from gaitlib.library import Library, library_status
from gaitlib.library.layout import ordered_pairs, shipped_library_dir
from gaitlib.training.recipe import Recipe

REPO = Path(__file__).resolve().parents[1]


def run(*commands: list[str], cwd: Path, env: dict) -> list[subprocess.CompletedProcess[str]]:
    """Each of ``commands`` (``gaitlib ARGS``), one after another as a user's shell would run them, in one child
    process started in ``cwd`` (importing torch once, not once a command): each command's exit code, stdout and
    stderr, through :func:`cli_runner.gaitlib_quick` of that folder's ``tests/``."""
    each = ("import json, sys\nfrom tests.cli_runner import gaitlib_quick\n"
            "done = [gaitlib_quick(*args) for args in json.loads(sys.argv[1])]\n"
            "print(json.dumps([[d.returncode, d.stdout, d.stderr] for d in done]))\n")
    child = subprocess.run([sys.executable, "-c", each, json.dumps(commands)], capture_output=True, text=True,
                           cwd=cwd, timeout=600, env=env)
    assert child.returncode == 0, child.stderr
    results = json.loads(child.stdout.splitlines()[-1])
    return [subprocess.CompletedProcess(["gaitlib", *args], *result) for args, result in zip(commands, results,
                                                                                              strict=True)]


def run_fix(commands: list[str], library: Path) -> None:
    """Run the collect and fit commands ``gaitlib library`` printed, as printed but for the collection's 64 worlds
    instead of 256 (a choice of the machine, not of the samples: at the tests' few dozen samples, the fastest here)
    and the fit's ``--min-per-label 0`` (the tiny library's few samples a pair cannot validate a fit), and check that
    nothing is left to fix."""
    collect, fit = commands
    collected = gaitlib_quick(*shlex.split(collect)[1:], "--worlds", "64")
    assert collected.returncode == 0, collected.stderr
    fitted = gaitlib_quick(*shlex.split(fit)[1:], "--min-per-label", "0")
    assert fitted.returncode == 0, fitted.stderr
    after = json.loads(gaitlib_quick("library", "--library", str(library), "--json").stdout)
    assert after["problems"] == [] and {v["state"] for v in after["switching"]["pairs"].values()} == {"covered"}


def test_training_a_gait_leaves_the_shipped_library_and_the_readme_main_job_alone(fresh_copy) -> None:
    env = {k: v for k, v in os.environ.items() if k != "GAITLIB_LIBRARY"}
    trained, main_job, refused = run(
        ["train", "stand", "--iterations", "1", "--worlds", "64", "--eval-episodes", "2", "--eval-seconds", "1"],
        ["run", "--from", "trot", "--to", "stand", "--json"],  # the README's main job on the shipped library
        ["train", "stand", "--iterations", "1", "--library", "library"],
        cwd=fresh_copy, env=env,
    )
    assert trained.returncode == 0, trained.stderr
    assert "runs/library is your own library, made now as a copy of the shipped" in trained.stderr
    stale = [line for line in trained.stderr.splitlines() if line.startswith("next: the switching models do not")]
    gaits = Library(fresh_copy / "library").gaits()
    others = [g for g in gaits if g != "stand"]
    assert len(stale) == 1 and f"drive {2 * len(others)} pair(s)" in stale[0]  # the stand's, both ways
    assert all(f"{a}-{b}" in stale[0] for g in others for a, b in (("stand", g), (g, "stand")))
    assert "the data they were fitted on are not here, so every pair is collected again" in stale[0]
    assert f"--pairs {','.join(ordered_pairs(gaits))} " in stale[0]
    assert git("status", "--porcelain", "--", "library", cwd=fresh_copy) == ""
    mine = Library(fresh_copy / "runs" / "library")
    assert mine.gaits() == gaits and len(gaits) == 14
    training = mine.entry("stand").metadata["training"]
    assert training["iterations"] == 1 and training["preset"]["name"] == "cpu" and training["preset"]["num_envs"] == 64
    assert mine.entry("stand").metadata["evaluation"]["seconds"] == 1.0
    shipped = Library(fresh_copy / "library")
    assert mine.entry("trot").identity == shipped.entry("trot").identity
    assert mine.entry("stand").identity != shipped.entry("stand").identity

    assert main_job.returncode == 0, main_job.stderr
    report = json.loads(main_job.stdout)  # the README's main job on the shipped library, seed 0
    assert [(s["from"], s["to"]) for s in report["switches"]] == [("trot", "stand")]
    assert report["switches"][0]["switch_s"] >= 2.0 - 1e-6 and report["stayed_up"] and report["fell_s"] is None
    assert report["falls"] == "trunk" and (fresh_copy / "run.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.startswith("gaitlib: error: gaitlib train would rewrite the entry stand of the shipped "
                                     "library, library;")
    assert refused.stderr.count("\n") == 1 and "--replace" in refused.stderr
    assert git("status", "--porcelain", "--untracked-files=all", cwd=fresh_copy) == ""  # all it wrote is ignored


def test_every_writing_command_with_its_defaults_leaves_a_fresh_clone_clean(fresh_copy) -> None:
    """The documented commands that write, with their defaults but for sizes, on a fresh clone: each writes into the
    user's own library (made from the shipped one) or under ignored folders; ``git status`` stays empty (``train``
    and ``run``: the test above). One child process runs them one after another, as a user's shell would, importing
    torch once."""
    env = {k: v for k, v in os.environ.items() if k != "GAITLIB_LIBRARY"}
    commands = [
        ["eval", "stand", "--record", "--episodes", "2", "--seconds", "1"],
        ["routes", "--samples", "1", "--worlds", "64"],  # a round of trials: its 42 pairs at once
        ["collect", "--samples", "4", "--pairs", "trot-stand", "--worlds", "4"],
        ["map", "data/transitions.h5"],
        ["benchmark", "--strategies", "random", "--magnitudes", "0", "--samples", "1", "--pairs", "trot-stand",
         "--worlds", "2"],
    ]
    for done in run(*commands, cwd=fresh_copy, env=env):
        assert done.returncode == 0, done.stderr
    mine = Library(fresh_copy / "runs" / "library")
    assert json.loads((mine.root / "stand" / "metadata.json").read_text())["evaluation"]["episodes"] == 2
    assert (mine.switching_dir / "routes.json").is_file()
    assert git("status", "--porcelain", "--untracked-files=all", cwd=fresh_copy) == ""


def test_the_tests_preset_stays_out_of_a_library_of_trained_gaits(tmp_path) -> None:
    mine = tmp_path / "mine"
    shutil.copytree(shipped_library_dir(), mine)
    listed = sorted(p.name for p in mine.iterdir())
    for library in (mine, shipped_library_dir()):
        result = gaitlib_quick("train", "walk", "--preset", "tiny", "--library", str(library), "--replace")
        assert result.returncode == 2
        assert "the 'tiny' preset is for tests (it learns nothing) and writes only into a library of its own" in (
            result.stderr
        )
    assert sorted(p.name for p in mine.iterdir()) == listed  # no walk, no staging folder, no lock


@pytest.mark.parametrize(("folder", "gaits"), [
    ("library", ("bound", "catch", "pace", "pronk", "sidestep_left", "sidestep_right", "stand", "trot", "trot_back",
                 "trot_in_place", "trot_left", "trot_right", "turn_left", "walk")),
    ("library-switch-start", ("bound", "pace", "pronk", "stand", "trot", "walk")),
    ("library-paper", ("pace", "stand", "trot")),
])
def test_every_library_in_the_repository_is_whole(folder, gaits) -> None:
    """The shipped library (six gaits, the recovery skill, six steering skills and the catch skill) and the two
    shipped before it
    (switch-start, the paper's recipe): every gait's policy, every ordered pair covered by switching models fitted on
    these very policies (identities and checksums agree), nothing to fix."""
    status = json.loads(gaitlib_quick("library", "--library", str(REPO / folder), "--json").stdout)
    assert status["problems"] == [] and sorted(status["gaits"]) == list(gaits)
    assert set(status["switching"]["pairs"]) == set(ordered_pairs(gaits))
    assert {v["state"] for v in status["switching"]["pairs"].values()} == {"covered"}


def test_growing_the_library_left_its_entries_as_they_were() -> None:
    """The six gaits are the policies the library's stored evidence measured before it grew by the recovery skill,
    and the seven entries those the route measurement of the seven recorded before it grew by the steering skills
    and the thirteen entries those the growth's benchmark recorded before it grew by the catch skill (every
    measurement records each policy's identity): each growth added its skills and changed no entry. The steering
    skills and the catch skill are those of their staging folders, byte for byte."""
    grown = Library(REPO / "library")
    results = REPO / "docs" / "results"
    six = json.loads((results / "library" / "bench-0n.json").read_text())["result"]["library_identities"]
    seven = json.loads((results / "recover" / "routes.json").read_text())["result"]["policies"]
    assert len(six) == 6 and {gait: grown.identities()[gait] for gait in six} == six
    assert set(seven) - set(six) == {"trot_in_place"} and {gait: grown.identities()[gait] for gait in seven} == seven
    thirteen = json.loads((results / "growth" / "bench-fitted-0n.json").read_text())["result"]["library_identities"]
    assert len(thirteen) == 13 and {gait: grown.identities()[gait] for gait in thirteen} == thirteen
    assert set(grown.gaits()) - set(thirteen) == {"catch"}
    steering = set(thirteen) - set(seven)
    assert steering == {"sidestep_left", "sidestep_right", "trot_back", "trot_left", "trot_right", "turn_left"}
    staging = {"sidestep_left": "library-mirror", "catch": "library-catch"}
    for gait in steering | {"catch"}:
        staged = REPO / staging.get(gait, "library-steer") / gait
        assert all((grown.root / gait / name).read_bytes() == (staged / name).read_bytes()
                   for name in ("metadata.json", "policy.pt", "policy.onnx")), gait


def test_the_grown_libraries_old_pairs_are_served_by_the_net_fitted_before_it_grew() -> None:
    """The shipped transition-net is a composite of three fits (gaitlib fit --extend): the first serves the seven
    entries' 42 pairs and was fitted on their policies (the identities its route measurement recorded), the second
    the 114 pairs with a steering skill, the third the 26 pairs with the catch skill."""
    from gaitlib.transition_net import load_parts

    lib = Library(REPO / "library")
    seven = json.loads((REPO / "docs" / "results" / "recover" / "routes.json").read_text())["result"]["policies"]
    old, new, catch = load_parts(lib.net_path, identities=lib.identities(), sources=())
    assert {f"{m}-{n}" for m, n in old.pairs} == set(ordered_pairs(tuple(seven)))
    assert old.metadata["library_identities"] == seven
    assert len(new.pairs) == 114 and not set(old.pairs) & set(new.pairs)
    assert len(catch.pairs) == 26 and all("catch" in pair for pair in catch.pairs)
    assert not (set(old.pairs) | set(new.pairs)) & set(catch.pairs)


@pytest.mark.parametrize(("folder", "skills", "problems"), [
    ("library-steer", ["sidestep_left", "sidestep_right", "trot_back", "trot_left", "trot_right", "turn_left"],
     ["no switching models yet (transition-net, TMT)"]),
])
def test_the_staged_skills_are_whole_entries_awaiting_their_switching_models(folder, skills, problems) -> None:
    """library-steer holds the six steering skills, each a whole entry (policy, identity, evaluation); their one
    problem is the switching models they do not have yet."""
    status = json.loads(gaitlib_quick("library", "--library", str(REPO / folder), "--json").stdout)
    assert sorted(status["gaits"]) == skills
    assert all(g["problem"] is None and g["eval_episodes"] == 256 for g in status["gaits"].values())
    assert [p["text"] for p in status["problems"]] == problems


def readme_recipe(readme: Path) -> Recipe:
    """The recipe a library's README trains every gait with: its ``R="..."`` line of ``gaitlib train``
    options."""
    line = next(text for text in readme.read_text().splitlines() if text.startswith('R="'))
    tokens = shlex.split(line.removeprefix("R=").strip('"'))
    pairs = zip(tokens[::2], tokens[1::2], strict=True)
    options = {key.removeprefix("--").replace("-", "_"): value for key, value in pairs}
    low, high = options.pop("kick_interval").split(":")
    words = {key: options.pop(key) for key in ("push_kind", "kick_draw", "terminate")}  # as an entry records them
    return Recipe.from_record(words | {"kick_interval": [float(low), float(high)]}
                              | {k: float(v) for k, v in options.items()})


def test_the_shipped_library_is_the_recipe_and_the_table_its_readme_gives() -> None:
    """Every entry of the shipped library passes its schema and checksums, was trained with the robust recipe of its
    README's commands (the recovery skill with its kicks of 1.5 m/s; the mirrored sidestep_left made from the trained
    sidestep_right), and its stored evaluation is the stored evidence of the quality bar (and, for the seven first
    entries, the README's table row); the walk, the bound and the pronk from the states of this library's own trot,
    pace and stand; the catch skill with its catch task, trained without kicks from the states of the seven first
    entries; its switching models drive all 182 pairs of the fourteen entries as they are, labelled the field's way,
    and its survival estimate is current, its catch table catching into the catch skill alone. It ships no route table
    (measured with the models before it grew)."""
    from gaitlib.strategies.survival import load_survival

    lib = Library(REPO / "library")
    status = library_status(lib)
    assert [g.problem for g in status.gaits] == [None] * len(status.gaits) and len(status.gaits) == 14
    assert status.problems == () and len(status.pairs) == 182 and set(status.pairs.values()) == {"covered"}
    assert set(status.falls().values()) == {"trunk"}
    estimate = load_survival(lib, status.bundle.gaits)
    assert estimate.horizon_s > 0 and estimate.info["catches"]["into"] == ["catch"]
    assert {d for row in estimate.info["catches"]["catch_into"].values() for d in row.values()} == {"catch"}
    assert not (lib.switching_dir / "routes.json").exists()
    results = REPO / "docs" / "results"
    recipe, readme = readme_recipe(lib.root / "README.md"), (lib.root / "README.md").read_text()
    identities = lib.identities()
    assert recipe.push_kind == "kick" and recipe.falls == "trunk"
    evidence = {"trot_in_place": "recover", "sidestep_left": "mirror", "catch": "catch",
                **dict.fromkeys(("sidestep_right", "trot_back", "trot_left", "trot_right", "turn_left"), "steer")}
    for gait in lib.gaits():
        metadata = json.loads((lib.root / gait / "metadata.json").read_text())
        if gait == "sidestep_left":  # the mirror image of the trained sidestep_right
            assert metadata["training"]["mirror"]["source_sha256"] == identities["sidestep_right"]
        elif gait == "catch":  # the catch task: the recipe without its kicks, from the seven first entries' states
            assert metadata["description"]["task"] == "catch"
            assert Recipe.from_record(metadata["training"]["recipe"]) == dataclasses.replace(recipe, kick_max=0.0)
            start = metadata["training"]["switch_start"]
            assert start["from_identities"] == {g: identities[g] for g in start["from_gaits"]} and len(start) > 0
        else:
            skill = gait == "trot_in_place"  # the recovery skill: the recipe but for its larger kicks
            assert Recipe.from_record(metadata["training"]["recipe"]) == (
                dataclasses.replace(recipe, kick_max=1.5) if skill else recipe), gait
        evaluation = metadata["evaluation"]
        assert (evaluation["episodes"], evaluation["seconds"], evaluation["falls"]) == (256, 20.0, "trunk")
        if gait not in evidence or gait == "trot_in_place":  # the seven first entries: the README's table
            row = next(text for text in readme.splitlines() if text.startswith(f"| `{gait}` |")).split(" | ")
            assert row[2] == f"{round(evaluation['fall_rate'] * 256)} of 256", (gait, row)
            assert row[-1] == f"{evaluation['median_heading_change_deg']:.1f} deg |", (gait, row)
        quality_bar = json.loads((results / evidence.get(gait, "library") / f"eval-{gait}.json").read_text())
        shared = [k for k in evaluation if k in quality_bar["result"]]
        assert len(shared) >= 20 and all(quality_bar["result"][k] == evaluation[k] for k in shared), gait
        if gait in ("walk", "bound", "pronk"):  # from the states this library's first three hand over
            start = metadata["training"]["switch_start"]
            assert start["from_identities"] == {g: identities[g] for g in ("pace", "stand", "trot")}, gait


def test_the_switch_start_library_grew_without_touching_its_first_gaits() -> None:
    """The walk, the bound and the pronk of the library shipped before the robust one were trained alone, from
    handover states of the trot, the pace and the stand exactly as that library holds them (their identities recorded
    in each new entry): growing it to six gaits rewrote none of the first three."""
    lib = Library(REPO / "library-switch-start")
    status = json.loads(gaitlib_quick("library", "--library", str(lib.root), "--json").stdout)
    first = ("pace", "stand", "trot")
    identities = lib.identities()
    for gait in ("bound", "pronk", "walk"):
        start = status["gaits"][gait]["switch_start"]
        assert start["share"] == 0.4 and start["from_gaits"] == list(first)
        assert start["from_identities"] == {g: identities[g] for g in first}


def test_a_retrained_gait_is_named_stale_with_the_commands_that_fix_it(
    switching_library, tmp_path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    library = copy_library(Library(switching_library), tmp_path / "library")
    before = library.entry("stand").identity
    fine = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    assert fine["problems"] == [] and set(fine["switching"]["pairs"]) == {"stand-trot", "trot-stand"}

    trained = gaitlib_quick("train", "trot", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "1",
                            "--eval-seconds", "0.5", "--seed", "5", "--library", str(library.root), "--run-dir",
                            str(tmp_path / "runs"))
    assert trained.returncode == 0, trained.stderr
    assert f"replacing {library.root / 'trot'}: the switching models there were fitted on the old trot" in (
        trained.stderr
    )
    status = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    assert {p: v["state"] for p, v in status["switching"]["pairs"].items()} == {
        "stand-trot": "stale", "trot-stand": "stale"
    }
    (problem,) = status["problems"]
    assert "do not drive 2 pair(s), stand-trot, trot-stand (retrained since the fit: trot)" in problem["text"]
    collect, fit = problem["commands"]
    assert collect.startswith(f"gaitlib collect --library {library.root} --pairs stand-trot,trot-stand --samples ")
    assert fit.startswith(f"gaitlib fit --library {library.root} --data ")

    refused = gaitlib_quick("run", "--from", "trot", "--to", "stand", "--library", str(library.root))
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert f"fix: {collect} && {fit}" in refused.stderr

    run_fix(problem["commands"], library.root)
    assert Library(library.root).entry("stand").identity == before

    ran = gaitlib_quick("run", "--from", "trot", "--to", "stand", "--library", str(library.root), "--hold", "1",
                        "--json")
    assert ran.returncode == 0, ran.stderr
    assert "stayed_up" in json.loads(ran.stdout)


def test_models_drive_their_pairs_and_a_grown_library_needs_only_its_new_pairs_old_policies_untouched(
    switching_library, tmp_path, monkeypatch
):
    from gaitlib.atomic import file_sha256
    from gaitlib.errors import GaitlibError
    from gaitlib.gaits import get_gait
    from gaitlib.meta import load_switching
    from gaitlib.meta.episode import run_episode
    from gaitlib.training import get_preset
    from gaitlib.training.trainer import TrainRequest, train_gait

    monkeypatch.chdir(tmp_path)
    library = copy_library(Library(switching_library), tmp_path / "library")
    old = {g: (library.entry(g).identity, file_sha256(library.root / g / "policy.pt")) for g in library.gaits()}
    train_gait(TrainRequest(description=get_gait("pace"), preset=get_preset("tiny"), iterations=1,
                            library=library.root, run_dir=tmp_path / "runs", backend="mujoco", eval_episodes=1,
                            eval_seconds=0.3))  # a gait added after the fit
    status = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    states = {p: v["state"] for p, v in status["switching"]["pairs"].items()}
    assert states == {"pace-stand": "uncovered", "pace-trot": "uncovered", "stand-pace": "uncovered",
                      "stand-trot": "covered", "trot-pace": "uncovered", "trot-stand": "covered"}
    setup = load_switching(library.root)
    assert setup.gaits == ("stand", "trot")
    trace = run_episode(setup, source="trot", dests=["stand"], strategy="net", request_s=0.2, hold_s=0.4,
                        deadline_s=0.3, backend="mujoco")
    assert all(t >= 0.2 - 1e-6 for t in trace.switches_s)
    with pytest.raises(GaitlibError, match=r"drive stand, trot, not pace; the switching models do not drive 4 pair"):
        run_episode(setup, source="pace", dests=["stand"], request_s=0.2, hold_s=0.4, backend="mujoco")

    # Growth as a user does it, by the commands `gaitlib library` prints: the new pairs alone are collected, the
    # models fitted on the old file and the new one; no old policy's bytes or identity change.
    (problem,) = status["problems"]
    assert "--pairs pace-stand,pace-trot,stand-pace,trot-pace " in problem["commands"][0]
    run_fix(problem["commands"], library.root)
    after = Library(library.root)
    assert {g: (after.entry(g).identity, file_sha256(after.root / g / "policy.pt")) for g in old} == old
