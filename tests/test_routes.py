"""Routes: the planner's choice, the route table's checks against the library, and a routed transition on the real
simulator counted once, a success only when every leg is."""

from __future__ import annotations

import dataclasses
import itertools
import json

import pytest
import torch
from cli_runner import gaitlib_quick
from conftest import copy_library

from gaitlib.benchmark.sweep import CellSchedule, SweepConfig, run_sweep
from gaitlib.defaults import Falls
from gaitlib.envs import EnvConfig
from gaitlib.errors import GaitlibError
from gaitlib.library.store import Library
from gaitlib.meta import SwitchTrials, TrialOutcome, TrialProtocol, load_switching
from gaitlib.sim import make_backend
from gaitlib.strategies.routes import ROUTES_FILE, RouteTable, load_routes

GAITS = ("pace", "stand", "trot")


def _table(rates: dict[str, tuple[int, int]], **fields) -> RouteTable:
    every = {f"{m}-{n}": (1000, 1000) for m in GAITS for n in GAITS if m != n} | rates
    return RouteTable(gaits=GAITS, strategy="net-lookahead", rates=every, policies={}, switching="", measured_with={},
                      **fields)


def test_a_detour_is_taken_only_where_it_beats_the_direct_switch_beyond_its_interval() -> None:
    table = _table({"trot-pace": (850, 1000), "trot-stand": (995, 1000), "stand-pace": (990, 1000)})
    assert table.route("trot", "pace") == ("stand", "pace")  # 0.985 predicted against 0.850 [0.826, 0.871]
    assert table.predicted(("trot", "stand", "pace")) == pytest.approx(0.995 * 0.990)
    assert table.expand("stand", ("trot", "pace", "stand")) == ("trot", "stand", "pace", "stand")
    assert table.detours() == {"trot-pace": ("trot", "stand", "pace")}
    assert _table({"trot-pace": (850, 1000)}, max_legs=1).route("trot", "pace") == ("pace",)
    close = _table({"trot-pace": (980, 1000), "trot-stand": (995, 1000), "stand-pace": (990, 1000)})
    assert close.route("trot", "pace") == ("pace",)  # 0.985 predicted, below 0.988: 980 of 1000's upper bound
    with pytest.raises(GaitlibError, match="lacks the pairs"):
        RouteTable(gaits=GAITS, strategy="x", rates={}, policies={}, switching="", measured_with={})


def test_the_routes_command_writes_a_table_that_a_refit_or_other_policies_make_stale(switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    measured = gaitlib_quick("routes", "--samples", "2", "--worlds", "4", "--backend", "mujoco", "--library",
                       str(library.root), "--out", str(tmp_path / "bench"), "--json")
    assert measured.returncode == 0, measured.stderr
    written = json.loads(measured.stdout)
    assert set(written["rates"]) == {"stand-trot", "trot-stand"} and written["detours"] == {}  # two gaits: direct
    assert all(n == 2 for _, n in written["rates"].values())
    table = load_routes(library, ("stand", "trot"))
    assert table.route("trot", "stand") == ("stand",)
    shown = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)["routes"]
    assert shown == {"state": "current", "strategy": "net-lookahead", "push_n": 0.0, "detours": {},
                     "falls": "trunk"}

    accuracy = library.accuracy_path
    accuracy.write_text(accuracy.read_text() + " ")  # as a refit would: other switching models, checksums and all
    library.write_checksums(library.switching_dir)
    with pytest.raises(GaitlibError, match=r"other switching models.*gaitlib routes --library"):
        load_routes(library, ("stand", "trot"))
    shown = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)["routes"]
    assert shown["state"] == "stale" and "other switching models" in shown["why"]
    ran = gaitlib_quick("run", "--routed", "--library", str(library.root), "--plot", str(tmp_path / "r.png"))
    assert ran.returncode == 2 and "other switching models" in ran.stderr.strip().splitlines()[0]
    (library.switching_dir / ROUTES_FILE).unlink()
    with pytest.raises(GaitlibError, match="has no route table"):
        load_routes(library, ("stand", "trot"))


def test_run_routed_follows_a_committed_route_table(tmp_path) -> None:
    """``gaitlib run --routed`` on the switch-start library takes its trot to the pace through the gait its route
    table names; the shipped library, which holds no route table since it grew, refuses --routed in one line."""
    committed = Library(Library().root.parent / "library-switch-start")
    route = json.loads((committed.switching_dir / ROUTES_FILE).read_text())["detours"]["trot-pace"]
    assert route[0] == "trot" and route[-1] == "pace" and len(route) == 3  # the trot goes to the pace through a gait
    ran = gaitlib_quick("run", "--from", "trot", "--to", "pace", "--routed", "--request-at", "0.3", "--hold", "0.7",
                        "--library", str(committed.root), "--plot", str(tmp_path / "run.png"), "--backend", "mujoco",
                        "--json")
    assert ran.returncode == 0, ran.stderr
    report = json.loads(ran.stdout)
    assert report["asked"] == ["pace"] and report["to"] == route[1:]
    legs = list(itertools.pairwise(route))
    assert [(s["from"], s["to"]) for s in report["switches"]] in (legs, legs[:1])  # a fall ends the run
    refused = gaitlib_quick("run", "--from", "trot", "--to", "pace", "--routed", "--plot", str(tmp_path / "no.png"))
    assert refused.returncode == 2 and "has no route table" in refused.stderr and refused.stderr.count("\n") == 1
    assert not (tmp_path / "no.png").exists()


class _Legs(CellSchedule):
    """The benchmark's schedule, each leg's outcome and each fall between legs kept."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.legs: list[tuple[int, bool]] = []
        self.between = 0

    def finished(self, outcome: TrialOutcome) -> None:
        super().finished(outcome)
        self.legs += list(zip(outcome.pair.tolist(), outcome.success.tolist(), strict=True))

    def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        again = super().source_fell(worlds, pairs)
        self.between += int((~again).sum())
        return again


def test_a_routed_transition_is_one_trial_that_succeeds_only_when_every_leg_does() -> None:
    setup = load_switching(None)  # the shipped library: trot, pace, stand
    trot, pace, stand = (setup.gait_index(g) for g in ("trot", "pace", "stand"))
    trials = 12
    schedule = _Legs([[(trot, stand), (stand, pace)], [(pace, trot)]], [("trot", "pace"), ("pace", "trot")], trials,
                     lambda _: None)
    protocol = TrialProtocol(warmup_s=0.7, source_extra_s=0.5, horizon_s=1.0, deadline_s=1.0, chain=True)
    sim = make_backend("mujoco", num_worlds=4)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=1e6), seed=3)
        controller = setup.controller(env, "random", deadline_s=protocol.deadline_s, seed=5)
        SwitchTrials(controller, protocol, schedule, seed=7).run()
    finally:
        sim.close()
    routed, direct = schedule.cells[("trot", "pace")], schedule.cells[("pace", "trot")]
    first = [ok for leg, ok in schedule.legs if leg == 0]
    second = [ok for leg, ok in schedule.legs if leg == 1]
    assert routed.samples == direct.samples == trials and len(first) == trials  # one count per transition
    assert len(second) + schedule.between == sum(first)  # only a first leg that stayed up goes on
    assert routed.successes == sum(second) and direct.successes == sum(ok for leg, ok in schedule.legs if leg == 2)
    assert routed.switched == len(first) + len(second)  # random switches at each request: one switch a leg run


def test_a_routed_sweep_records_its_routes_and_resumes_only_with_them(tmp_path) -> None:
    setup = load_switching(None)
    protocol = TrialProtocol(warmup_s=0.3, source_extra_s=0.2, horizon_s=0.5, deadline_s=0.3, push_lead_s=0.2)
    config = SweepConfig(strategies=("random",), magnitudes=(0.0,), samples=3, pairs=(("trot", "pace"),),
                         num_worlds=2, protocol=protocol, backend="mujoco",
                         routes={"trot-pace": ("trot", "stand", "pace")})
    results = run_sweep(tmp_path / "bench", setup, config)
    cell = results["groups"]["random@0"]["cells"]["trot-pace"]
    assert cell["samples"] == 3 and 3 <= cell["switched"] <= 6  # a first switch each, a second after each that held
    assert results["settings"]["routes"] == {"trot-pace": ["trot", "stand", "pace"]}
    with pytest.raises(GaitlibError, match=r"other settings \(routes\)"):
        run_sweep(tmp_path / "bench", setup, dataclasses.replace(config, routes={}))
    with pytest.raises(GaitlibError, match="does not lead from one gait to another as trot-pace"):
        dataclasses.replace(config, routes={"trot-pace": ("trot", "stand")})
    strict = run_sweep(tmp_path / "strict", setup, dataclasses.replace(config, falls=Falls.CONTACT))
    assert strict["settings"]["falls"] == "contact" and results["settings"]["falls"] == "trunk"  # the default
    cell = strict["groups"]["random@0"]["cells"]["trot-pace"]
    assert cell["samples"] == 3 and 0 <= cell["touched"] <= 3 and cell["longest_touch_s"] >= 0


def _outcome(world: int, leg: int, success: bool) -> TrialOutcome:
    return TrialOutcome(world=torch.tensor([world]), pair=torch.tensor([leg]), success=torch.tensor([success]),
                        fall_after_s=torch.tensor([torch.inf if success else 0.5]), max_push=torch.zeros(1),
                        touched=torch.tensor([False]), longest_touch_s=torch.zeros(1))


def test_a_fall_between_the_legs_fails_the_routed_transition_once_and_the_world_takes_another() -> None:
    trot, pace, stand = 2, 0, 1
    schedule = CellSchedule([[(trot, stand), (stand, pace)], [(pace, trot)]], [("trot", "pace"), ("pace", "trot")],
                            2, lambda _: None)
    assert schedule.pairs == [(trot, stand), (stand, pace), (pace, trot)]  # the engine's pairs: every leg
    assert schedule.begin(3).tolist() == [0, 2, 0]  # each transition starts with its first leg
    schedule.finished(_outcome(0, 0, True))  # world 0's first leg stayed up: it goes on in the stand
    assert schedule.chain(torch.tensor([0]), torch.tensor([stand])).tolist() == [1]
    assert schedule.source_fell(torch.tensor([0]), torch.tensor([1])).tolist() == [False]  # fell in the stand
    assert schedule.source_fell(torch.tensor([2]), torch.tensor([0])).tolist() == [True]  # before the first request
    schedule.finished(_outcome(1, 2, True))
    assert schedule.chain(torch.tensor([1]), torch.tensor([trot])).tolist() == [-1]  # a direct pair: reset
    routed, direct = schedule.cells[("trot", "pace")], schedule.cells[("pace", "trot")]
    assert (routed.samples, routed.successes, routed.source_falls) == (1, 0, 1) and schedule.ended == 2
    assert (direct.samples, direct.successes) == (1, 1)


def test_a_source_fall_the_schedule_does_not_restart_gives_the_world_a_new_trial() -> None:
    class Abandoning(CellSchedule):
        def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
            self.abandoned = getattr(self, "abandoned", 0) + len(pairs)
            return torch.zeros(len(pairs), dtype=torch.bool)

    setup = load_switching(None)
    trot, stand = setup.gait_index("trot"), setup.gait_index("stand")
    schedule = Abandoning([[(trot, stand)]], [("trot", "stand")], 12, lambda _: None)
    protocol = TrialProtocol(warmup_s=0.7, source_extra_s=0.5, horizon_s=0.5, deadline_s=0.3)
    sim = make_backend("mujoco", num_worlds=4)
    try:  # pushes that fell many sources before their request
        env = setup.make_env(sim, EnvConfig(episode_seconds=1e6, pushes=protocol.pushes(400.0, fixed=True)), seed=3)
        controller = setup.controller(env, "random", deadline_s=protocol.deadline_s, seed=5)
        SwitchTrials(controller, protocol, schedule, seed=7).run()
    finally:
        sim.close()
    cell = schedule.cells[("trot", "stand")]
    assert schedule.abandoned > 0 and cell.samples + schedule.abandoned == 12  # each begun trial ends one way
