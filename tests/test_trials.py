"""The switch trial is one engine: the collection's labels are the benchmark's verdicts on the same trials, and
``gaitlib run`` is one of those trials on one robot."""

from __future__ import annotations

import numpy as np
import pytest

from gaitlib.benchmark.sweep import CellSchedule
from gaitlib.collection.chunks import ChunkSamples
from gaitlib.envs import EnvConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta import SwitchTrials, TrialOutcome, TrialProtocol, load_switching
from gaitlib.sim import make_backend

TRIALS = 10
TIMES = {"warmup_s": 0.7, "source_extra_s": 0.5, "horizon_s": 1.0, "deadline_s": 1.0}


class _Verdicts(CellSchedule):
    """The benchmark's schedule, the verdicts kept in the order the trials ended."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.order: list[bool] = []

    def finished(self, outcome: TrialOutcome) -> None:
        super().finished(outcome)
        self.order += outcome.success.tolist()


def _run(setup, protocol: TrialProtocol, schedule_for):
    """One world, the same environment, source-time and phase seeds: run ``schedule_for(controller)``'s trials."""
    sim = make_backend("mujoco", num_worlds=1)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=1e6), seed=3)
        controller = setup.controller(env, "random", deadline_s=protocol.deadline_s, seed=5)
        schedule = schedule_for(controller)
        SwitchTrials(controller, protocol, schedule, seed=7, on_switch=getattr(schedule, "record", None)).run()
        return schedule
    finally:
        sim.close()


def test_the_collections_labels_are_the_benchmarks_random_verdicts() -> None:
    setup = load_switching(None)  # the shipped library: about 80% of random trot-to-pace switches stay up
    pair = (setup.gait_index("trot"), setup.gait_index("pace"))
    # One protocol for both (the collection's own pushes only while the source runs: at 0 N that changes no physics,
    # but its push timers draw from the environment's random stream at other moments).
    protocol = TrialProtocol(**TIMES)
    collected = _run(
        setup, protocol,
        lambda ctl: ChunkSamples(ctl, [pair], np.array([TRIALS]), ctl.policies[0].latent_dim, seed=11),
    ).take()
    judged = _run(setup, protocol, lambda ctl: _Verdicts([[pair]], [("trot", "pace")], TRIALS, lambda _: None))
    labels = collected.success.astype(bool).tolist()
    assert len(labels) == TRIALS and labels == judged.order  # trial by trial, not only the counts
    assert 0 < sum(labels) < TRIALS  # both outcomes occur, so the agreement is not a constant
    cell = judged.cells[("trot", "pace")]
    assert cell.samples == TRIALS and cell.successes == sum(labels) and cell.switched == TRIALS
    assert cell.forced == 0 and cell.wait_s == 0.0  # random switches at the request
    falls = collected.fall_after[~collected.success.astype(bool)]
    assert np.all((falls > 0) & (falls <= TIMES["horizon_s"] + 1 / 30 + 1e-6))


def test_a_protocol_with_impossible_times_is_refused_in_one_line() -> None:
    refused = (
        ({"horizon_s": 0.0}, "the horizon must be positive"),
        ({"warmup_s": float("nan")}, r"the trial's times \(.*\) must be finite"),
        ({"push_lead_s": 2.0}, r"the push lead must lie in \[0, warm-up time\]"),
        ({"push_window": "always"}, "push window 'always': request or source"),
    )
    for fields, message in refused:
        with pytest.raises(GaitlibError, match=message):
            TrialProtocol(**fields)
