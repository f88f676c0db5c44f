"""``gaitlib bench``: speed measurements that report ratios against a reference measured in the same run."""

from __future__ import annotations

import json
import os

import typer

__all__ = ["app"]

app = typer.Typer(help="Throughput benchmarks (ratios against plain MuJoCo C measured in the same run).")


@app.command("sim")
def sim(
    backend: str = typer.Option("mujoco", "--backend", help="auto, mujoco or newton."),
    worlds: int = typer.Option(256, "--worlds", help="Number of parallel worlds."),
    seconds: float = typer.Option(10.0, "--seconds", help="Wall-clock seconds spent on each side."),
    threads: int = typer.Option(os.cpu_count() or 1, "--threads", help="CPU threads for the references."),
    device: str | None = typer.Option(None, "--device", help="Torch device for the backend (default: its own)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
) -> None:
    """Control steps per second of a backend against plain MuJoCo C on the same in-contact worlds."""
    from gaitlib.bench.sim_throughput import measure_throughput
    from gaitlib.sim import make_backend

    sim_backend = make_backend(backend, num_worlds=worlds, device=device)
    try:
        result = measure_throughput(sim_backend, seconds=seconds, threads=threads)
    finally:
        sim_backend.close()
    if as_json:
        print(json.dumps(result.as_dict()))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"sim throughput: {result.backend} on {result.device}, {result.worlds} worlds")
    table.add_column("measure")
    table.add_column("control steps/s", justify="right")
    table.add_row(f"gaitlib {result.backend} backend", f"{result.env_steps_per_s:,.0f}")
    table.add_row("MuJoCo C mj_step thread pool", f"{result.raw_mj_step_per_s:,.0f}")
    table.add_row("MuJoCo C rollout (chained)", f"{result.raw_rollout_per_s:,.0f}")
    table.add_row("ratio (backend / faster reference)", f"{result.ratio:.3f}")
    Console().print(table)
