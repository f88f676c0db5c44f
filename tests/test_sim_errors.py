"""Bad input to the simulation layer gets one clear error."""

from __future__ import annotations

import copy
import dataclasses

import pytest
import torch

import gaitlib.sim
from gaitlib.errors import SimulationError, UnknownNameError
from gaitlib.robots import get_robot
from gaitlib.sim import make_backend


def test_unknown_backend() -> None:
    with pytest.raises(UnknownNameError, match="unknown backend 'bullet'"):
        make_backend("bullet", num_worlds=1)


def test_unknown_robot() -> None:
    with pytest.raises(UnknownNameError, match="unknown robot 'spot'"):
        make_backend("mujoco", num_worlds=1, robot="spot")


def test_zero_worlds() -> None:
    with pytest.raises(SimulationError, match="at least one world"):
        make_backend("mujoco", num_worlds=0)


def test_missing_model_file(tmp_path) -> None:
    robot = dataclasses.replace(get_robot("a1"), mjcf_path=tmp_path / "nope.xml")
    with pytest.raises(SimulationError, match="model file not found"):
        make_backend("mujoco", num_worlds=1, robot=robot)


def test_malformed_model_file(tmp_path) -> None:
    path = tmp_path / "broken.xml"
    path.write_text("<mujoco><worldbody><body></mujoco>")
    robot = dataclasses.replace(get_robot("a1"), mjcf_path=path)
    with pytest.raises(SimulationError, match="cannot load robot model"):
        make_backend("mujoco", num_worlds=1, robot=robot)


def test_backend_that_cannot_be_imported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(gaitlib.sim, "_BACKENDS", copy.deepcopy(gaitlib.sim._BACKENDS))
    gaitlib.sim.register_backend("missing", "gaitlib.sim.no_such_module:Backend")
    with pytest.raises(SimulationError, match="backend 'missing' is not available here"):
        make_backend("missing", num_worlds=1)


def test_mujoco_backend_refuses_a_gpu_device() -> None:
    with pytest.raises(SimulationError, match="CPU only"):
        make_backend("mujoco", num_worlds=1, device="cuda:0")


def test_non_finite_targets_are_refused() -> None:
    backend = make_backend("mujoco", num_worlds=2)
    targets = torch.zeros(2, 12)
    targets[1, 3] = float("nan")
    with pytest.raises(SimulationError, match=r"non-finite PD targets for worlds \[1\]"):
        backend.set_pd_targets(targets)
    backend.close()
