"""``gaitlib gaits``: the gaits gaitlib knows, and whether each reference can be followed."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text

__all__ = ["gaits_command"]


def gaits_command(
    names: list[str] | None = typer.Argument(None, help="Gaits to show (default: every shipped description)."),
    gait_file: list[Path] | None = typer.Option(None, "--gait-file", help="A TOML gait description (repeatable)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object per gait instead of a table."),
) -> None:
    """List gait descriptions (forward and lateral speed, yaw rate, cycle, duty) with a physical check of each
    reference: the trunk rotation its feet cannot carry and its flights, before any training. A description whose
    feet cannot carry it at all (out of reach, beyond a joint limit, a foot swept into another leg's room by a turn
    or sidestep) is refused in one line."""
    from dataclasses import asdict

    from gaitlib.gaits import clip_from_description, gait_names, get_gait, load_gait_file
    from gaitlib.gaits.feasibility import TILT_LIMIT_DEG, check_reference

    files = [load_gait_file(path) for path in gait_file or []]
    descriptions = [get_gait(name) for name in names or ([] if files else gait_names())] + files
    clips = [clip_from_description(d) for d in descriptions]  # every description refused or built before any check
    checks = [(d, check_reference(clip)) for d, clip in zip(descriptions, clips, strict=True)]
    if as_json:
        for d, check in checks:
            print(json_text({"description": asdict(d), "check": asdict(check) | {"followable": check.followable}}))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    table = Table(title=f"gaits: the trunk rotation each reference needs and does not have (warning above "
                        f"{TILT_LIMIT_DEG:g} deg), its flights and steady lean (docs/training.md)")
    for column in ("gait", "forward m/s", "lateral m/s", "yaw rad/s", "cycle s", "duty", "roll deg", "pitch deg",
                   "ZMP outside", "flight ms", "free fall cm", "lean cm", "followable"):
        table.add_column(column, justify="left" if column in ("gait", "followable") else "right")
    for d, c in checks:
        table.add_row(
            d.name, f"{d.forward_speed:.2f}", f"{d.lateral_speed:.2f}", f"{d.yaw_rate:.2f}", f"{d.period:.3f}",
            f"{d.duty_factor:.2f}", f"{c.tilt_deg[0]:.1f}", f"{c.tilt_deg[1]:.1f}", f"{c.outside_share:.0%}",
            f"{c.flight_s * 1000:.0f}",
            f"{c.flight_drop_m * 100:.1f}", f"{c.steady_shift_m * 100:.1f}", "yes" if c.followable else "unlikely",
        )
    table_console().print(table)
