"""Shared fixtures: backends on the real simulators, at small sizes."""

from __future__ import annotations

import pytest

from gaitlib.sim import make_backend

BACKENDS = [
    "mujoco",
    pytest.param("newton", marks=pytest.mark.newton),
]


@pytest.fixture(params=BACKENDS)
def backend_name(request: pytest.FixtureRequest) -> str:
    """Each simulation backend in turn (Newton runs on the CPU here: slow, so tests keep worlds few)."""
    return request.param


@pytest.fixture
def make(backend_name: str):
    """``make(num_worlds)`` builds the parametrized backend and closes it after the test."""
    built = []

    def build(num_worlds: int):
        backend = make_backend(backend_name, num_worlds=num_worlds, device="cpu")
        built.append(backend)
        return backend

    yield build
    for backend in built:
        backend.close()


@pytest.fixture(scope="session")
def switching_library(tmp_path_factory):
    """A library of two tiny one-iteration policies (stand, trot) with a transition-net and a TMT fitted on a small
    real collection: everything the strategies and the meta-controller load."""
    import dataclasses

    from gaitlib.gaits import get_gait
    from gaitlib.strategies import build_table, save_table
    from gaitlib.training import get_preset, load_entry
    from gaitlib.training.trainer import TrainRequest, train_gait
    from gaitlib.transition_net import FitConfig, fit, save_net
    from gaitlib.transitions import CollectConfig, collect, read

    root = tmp_path_factory.mktemp("switching")
    library = root / "library"
    tiny = dataclasses.replace(
        get_preset("cpu"), num_envs=4, steps_per_env=8, epochs=1, mini_batches=1, actor_hidden=(32, 16),
        critic_hidden=(32, 16),
    )
    gaits = ["stand", "trot"]
    for gait in gaits:
        train_gait(
            TrainRequest(
                description=get_gait(gait), preset=tiny, iterations=1, library=library, run_dir=root / "runs" / gait,
                backend="mujoco", eval_episodes=2, eval_seconds=0.5,
            )
        )
    data_path = root / "samples.h5"
    config = CollectConfig(
        samples=32, num_worlds=8, horizon_s=1.0, warmup_s=0.3, source_extra_s=0.5, push_max=400.0, backend="mujoco",
    )
    collect(data_path, library=library, gaits=gaits, config=config)
    data = read(data_path)
    save_net(library / "transition_net" / "net.pt", fit(data, FitConfig(epochs=2)))
    identities = {g: load_entry(library, g).identity for g in gaits}
    save_table(library / "tmt" / "tmt.json", build_table(data, identities=identities, source=str(data_path)))
    return library
