"""Shared fixtures: backends on the real simulators, at small sizes."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from gaitlib.atomic import CHECKSUM_KEY, json_checksum
from gaitlib.envs.observations import ObservationConfig
from gaitlib.library import Library
from gaitlib.sim import make_backend

REPO = Path(__file__).resolve().parents[1]
"""The repository the tests run in."""

TINY_GAITS = ("stand", "trot")
"""The gaits of :func:`tiny_library`."""

BACKENDS = [
    "mujoco",
    pytest.param("newton", marks=pytest.mark.newton),
]

LONGEST_FILES = (
    "test_user_library.py", "test_cluster.py", "test_distributed.py", "test_writers.py", "test_cli_train.py",
    "test_full_disk.py", "test_guard.py", "test_recipe.py", "test_cli_switching.py", "test_byte_flips.py",
    "test_transition_crash_safety.py", "test_cli_transitions.py", "test_routes.py", "test_data_identity.py",
    "test_packaging.py", "test_refusals.py", "test_drive.py",
)
"""The test files that take longest (``pytest --durations=0``), longest first, run after the Newton files: pytest-xdist
hands out whole units of work in collection order (``--no-loadscope-reorder``; by default it would order them by their
number of tests), so a long file collected last keeps one core busy while the other idles."""

NEWTON_FILES = (
    "tests/test_cli_throughput.py", "tests/test_gpu_check.py", "tests/test_meta.py", "tests/test_sim_backends.py",
    "tests/test_sim_parity.py",
)
"""The files with a test that runs the newton backend, in the test process or in a child. They are one unit of work
for pytest-xdist (:func:`pytest_xdist_make_scheduler`): one worker runs them one after another, so that Newton is
imported once (Warp parses every kernel's source at import: about 10 s on this CPU) and, with an empty kernel cache,
each kernel is compiled once (about 70 s on one core), not by both workers at the same time. A test of newton in a
file not listed here fails the run (:func:`pytest_collection_modifyitems`)."""


def _runs_newton(item: pytest.Item) -> bool:
    callspec = getattr(item, "callspec", None)
    return item.get_closest_marker("newton") is not None or item.path.name == "test_gpu_check.py" or (
        callspec is not None and callspec.params.get("backend_name") == "newton"
    )


def _file(nodeid: str) -> str:
    return nodeid.split("::")[0]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The Newton files first (:data:`NEWTON_FILES`), then the longest files (:data:`LONGEST_FILES`), the rest in
    their usual order."""
    unlisted = sorted({_file(item.nodeid) for item in items if _runs_newton(item)} - set(NEWTON_FILES))
    if unlisted:
        raise pytest.UsageError(f"tests/conftest.py: add {', '.join(unlisted)} to NEWTON_FILES (it runs newton)")
    rank = {name: i + 1 for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: 0 if _file(item.nodeid) in NEWTON_FILES else rank.get(item.path.name, len(rank) + 1))


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist: unknown when it is not loaded
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """pytest-xdist's ``--dist loadfile``, whole files to a worker in collection order, but with the Newton files one
    unit together. (Its own ``--dist loadgroup`` marks do not group under pytest 9: they rename node ids, which pytest
    9 no longer reads.)"""
    from xdist.scheduler import LoadScopeScheduling

    class FilesAndNewton(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return "newton" if _file(nodeid) in NEWTON_FILES else _file(nodeid)

    return FilesAndNewton(config, log)


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


def built_once(tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], None]) -> Path:
    """The folder ``name`` made by ``build(folder)`` once for the whole run: under pytest-xdist the first worker to
    ask builds it and the others wait for it and share it, as the tests of one process share it (read-only to
    the tests: copy it before writing)."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, above each worker's own
    folder, done = base / name, base / f"{name}.done"
    with open(base / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)  # a build interrupted before it was done
            build(folder)
            done.touch()
    return folder


@pytest.fixture(scope="session")
def tiny_library(tmp_path_factory) -> Library:
    """The tests' one trained library: stand and trot, one PPO iteration each with the tiny preset (real policies
    on the real simulator, untrained in effect). Shared by every test module (and worker): copy it
    (:func:`copy_library`) before writing into it."""
    from gaitlib.gaits import get_gait
    from gaitlib.training import get_preset
    from gaitlib.training.trainer import TrainRequest, train_gait

    def build(root: Path) -> None:
        for gait in TINY_GAITS:
            train_gait(
                TrainRequest(
                    description=get_gait(gait), preset=get_preset("tiny"), iterations=1, library=root / "library",
                    run_dir=root / "runs" / gait, backend="mujoco", eval_episodes=2, eval_seconds=0.5,
                )
            )

    return Library(built_once(tmp_path_factory, "tiny", build) / "library")


def write_foreign_json(path: Path, payload: dict) -> None:
    """Write ``payload`` with its matching checksum as another writer could: nan and infinities as Python's default
    writer spells them, which gaitlib's own writer refuses (a reader must still refuse them)."""
    path.write_text(json.dumps(payload | {CHECKSUM_KEY: json_checksum(payload)}))


def rsl_rl_models(*, actor_hidden: tuple[int, ...], critic_hidden: tuple[int, ...], activation: str = "elu",
                  observation: ObservationConfig) -> tuple[object, object]:
    """Fresh (untrained) rsl-rl actor and critic laid out as training makes them (``rsl_rl_config``): what
    ``Library.save_entry`` writes."""
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    obs = TensorDict({"policy": torch.zeros(1, observation.actor_dim),
                      "privileged": torch.zeros(1, observation.privileged_dim)}, batch_size=[1])
    groups = {"actor": ["policy"], "critic": ["policy", "privileged"]}
    actor = MLPModel(obs, groups, "actor", 12, hidden_dims=list(actor_hidden), activation=activation,
                     obs_normalization=True,
                     distribution_cfg={"class_name": "rsl_rl.modules.distribution.GaussianDistribution"})
    critic = MLPModel(obs, groups, "critic", 1, hidden_dims=list(critic_hidden), activation=activation,
                      obs_normalization=True)
    return actor, critic


def trained_models(library: Library, gait: str) -> tuple[object, object]:
    """The rsl-rl actor and critic of ``library``'s entry ``gait``, its ``policy.pt`` weights loaded: what
    ``Library.save_entry`` writes again."""
    entry = library.entry(gait)
    nets = entry.metadata["networks"]
    actor, critic = rsl_rl_models(actor_hidden=tuple(nets["actor_hidden"]), critic_hidden=tuple(nets["critic_hidden"]),
                                  activation=nets["activation"], observation=entry.observation)
    state = torch.load(library.root / gait / "policy.pt", weights_only=True)
    actor.load_state_dict(state["actor"])
    critic.load_state_dict(state["critic"])
    return actor, critic


def copy_library(library: Library, folder: Path) -> Library:
    """A writable copy of ``library`` in ``folder``."""
    shutil.copytree(library.root, folder)
    return Library(folder)


@pytest.fixture(scope="session")
def switching_library(tiny_library, tmp_path_factory) -> Path:
    """A copy of the tiny library with a transition-net and a TMT fitted (through :func:`fit_library`) on a small
    real collection: everything the strategies and the meta-controller load."""
    from gaitlib.collection import CollectConfig, collect
    from gaitlib.meta import TrialProtocol
    from gaitlib.strategies.fitting import fit_library
    from gaitlib.transitions import read

    def build(root: Path) -> None:
        library = copy_library(tiny_library, root / "library")
        data_path = root / "samples.h5"
        config = CollectConfig(
            samples=32, num_worlds=8, push_max=400.0, backend="mujoco",
            protocol=TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.5),
        )
        collect(data_path, library=library, config=config)
        fit_library(library, read(data_path), sources=[data_path], epochs=2, min_per_label=0)  # too few to validate

    return built_once(tmp_path_factory, "switching", build) / "library"


def git(*args: str, cwd: Path) -> str:
    """``git ARGS`` in ``cwd``, as a test user; its stdout."""
    command = ["git", "-c", "user.name=test", "-c", "user.email=test@example.org", *args]
    return subprocess.run(command, cwd=cwd, check=True, capture_output=True, text=True).stdout


@pytest.fixture
def fresh_copy(tmp_path) -> Path:
    """The repository's files as a fresh clone would hold them (this working tree's, committed in a new git repo)."""
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, check=True,
                            capture_output=True, text=True).stdout.split()
    copy = tmp_path / "gaitlib"
    for name in listed:
        if (REPO / name).is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, copy / name)
    git("init", "-q", cwd=copy)
    git("add", "-A", cwd=copy)
    git("commit", "-q", "-m", "fresh", cwd=copy)
    return copy
