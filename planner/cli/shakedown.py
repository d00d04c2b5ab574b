"""``rapt-plan shakedown``: design the range day's calibration run and write it as a plan to fly."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from planner.cli.console import fail, out, print_table
from planner.cli.inputs import load_mission
from rapt.errors import RaptError

__all__ = ["shakedown"]


def shakedown(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Directory for plan.json and the run's files.")],
    max_minutes: Annotated[
        float, typer.Option("--max-minutes", help="Longest the run may take, in minutes of vehicle time.")
    ] = 15.0,
    margin: Annotated[
        float, typer.Option(help="Metres the predicted track keeps from the area's edge and every element.")
    ] = 50.0,
    measure_s: Annotated[
        float, typer.Option("--measure-s", help="Seconds each leg is measured once the vehicle is steady.")
    ] = 60.0,
) -> None:
    """Design one calibration run (speeds, turns both ways, hold, ascent, dive, return) that fits the range.

    Fly it like a plan's scenario: rapt-plan run OUT/plan.json --scenario shakedown [--log X.mcap] [--mavlink ...].
    """
    from planner.plan.shakedown import ShakedownOptions, design_shakedown, write_shakedown

    mission = load_mission(mission_file)
    try:
        design = design_shakedown(mission, ShakedownOptions(max_minutes, margin, measure_s))
        path = write_shakedown(design, mission_file, out_dir)
    except (RaptError, OSError) as exc:
        fail(str(exc))
    table = Table(title=f"{mission.name}: calibration run (bearing {design.bearing_deg:.0f} deg)")
    for col in ("leg", "kind", "speed m/s", "turn deg", "surface", "start s", "end s"):
        table.add_column(col, justify="left" if col in ("leg", "kind") else "right")
    for leg in design.leg_entries():
        table.add_row(
            leg["name"],
            leg["kind"],
            f"{leg['speed']:.2f}",
            f"{leg['turn_deg']:+.0f}" if leg["kind"] == "turn" else "",
            "yes" if leg["surface"] else "",
            f"{leg['start_s']:.0f}",
            f"{leg['end_s']:.0f}",
        )
    print_table(table)
    clear = min(design.clearance.values())
    out.print(f"predicted: ends recovered at {design.end_s:.0f} s; closest approach {clear:.0f} m; {path}")
