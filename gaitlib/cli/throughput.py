"""``gaitlib throughput``: speed measurements that report ratios against a reference measured in the same run."""

from __future__ import annotations

import os
from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.options import CHUNK, MEASURE_SECONDS, PUSH_N, WORLDS, Bounds, bounded
from gaitlib.cli.tables import print_measures

__all__ = ["app"]

app = typer.Typer(help="Speed measurements (ratios against plain MuJoCo C measured in the same run).")


@app.command("sim")
def sim(
    backend: str = typer.Option("mujoco", "--backend", help="auto, mujoco or newton."),
    worlds: int = bounded(256, "--worlds", help="Number of parallel worlds;", bounds=WORLDS),
    seconds: float = bounded(10.0, "--seconds", help="Wall-clock time spent on each side;", bounds=MEASURE_SECONDS),
    threads: int = bounded(
        os.cpu_count() or 1,
        "--threads",
        help="CPU threads for the references;",
        bounds=Bounds(low=1, high=1024, whole=True),
    ),
    device: str | None = typer.Option(None, "--device", help="Torch device for the backend (default: its own)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
) -> None:
    """Control steps per second of a backend against plain MuJoCo C on the same in-contact worlds."""
    from gaitlib.cli.options import check_worlds
    from gaitlib.sim import make_backend
    from gaitlib.throughput.sim import measure_throughput

    check_worlds("--worlds", worlds, backend=backend)
    sim_backend = make_backend(backend, num_worlds=worlds, device=device)
    try:
        result = measure_throughput(sim_backend, seconds=seconds, threads=threads)
    finally:
        sim_backend.close()
    if as_json:
        print(json_text(result.as_dict()))
        return
    print_measures(
        f"sim throughput: {result.backend} on {result.device}, {result.worlds} worlds",
        [
            (f"gaitlib {result.backend} backend", f"{result.env_steps_per_s:,.0f}"),
            ("MuJoCo C mj_step thread pool", f"{result.raw_mj_step_per_s:,.0f}"),
            ("MuJoCo C rollout (chained)", f"{result.raw_rollout_per_s:,.0f}"),
            ("ratio (backend / faster reference)", f"{result.ratio:.3f}"),
        ],
        header=("measure", "control steps/s"),
    )


@app.command("collect")
def collect_throughput(
    worlds: int = bounded(256, "--worlds", help="Number of parallel worlds;", bounds=WORLDS),
    seconds: float = bounded(
        60.0, "--seconds", help="Wall-clock time per measurement (three are made);", bounds=MEASURE_SECONDS
    ),
    push_max: float = bounded(400.0, "--push-max", help="Largest push of the collection;", bounds=PUSH_N),
    chunk: int | None = bounded(
        None, "--chunk", help="Samples per chunk of the collection (default: collect's, 16 per world);", bounds=CHUNK
    ),
    backend: str = typer.Option("mujoco", "--backend", help="auto, mujoco or newton."),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
) -> None:
    """Samples per second of gaitlib collect against what the environment step allows (goal: ratio >= 0.8)."""
    from gaitlib.cli.options import check_worlds
    from gaitlib.library import Library
    from gaitlib.throughput.collect import measure_collect_throughput

    check_worlds("--worlds", worlds, backend=backend)
    result = measure_collect_throughput(
        Library(library), worlds=worlds, seconds=seconds, push_max=push_max, chunk=chunk, backend=backend
    )
    if as_json:
        print(json_text(result.as_dict()))
        return
    print_measures(
        f"collection throughput: {worlds} worlds, pushes up to {push_max:g} N",
        [
            ("policy rollout, control steps/s (reference)", f"{result.env_steps_per_s:,.0f}"),
            ("control steps per sample", f"{result.steps_per_sample:.1f}"),
            ("samples/s the environment step allows", f"{result.allowed_samples_per_s:.1f}"),
            ("samples/s collected", f"{result.samples_per_s:.1f}"),
            ("ratio", f"{result.ratio:.3f}"),
            ("time for 2e6 samples at this rate", f"{2e6 / result.samples_per_s / 3600:.1f} h"),
        ],
    )
