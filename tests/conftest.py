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
