"""``rapt-plan calibrate``: fit a mission's vehicle block to run logs and write a calibrated mission file."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from planner.cli.console import err, fail, out, print_table

__all__ = ["calibrate"]


def calibrate(
    mission: Annotated[Path, typer.Argument(help="The mission file (.toml) whose [vehicle] block is calibrated.")],
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="MCAP logs of runs of this mission (SIL or a real vehicle): a calibration run's alone, "
            "or at least two plan runs, or both."
        ),
    ],
    out_path: Annotated[
        Path, typer.Option("--out", help="Calibrated mission file to write (a .json sidecar is written beside it).")
    ] = Path("calibrated.toml"),
    seed: Annotated[int, typer.Option(help="Seed of the bootstrap behind the standard errors.")] = 0,
    bias: Annotated[
        Path | None,
        typer.Option(
            "--bias",
            help="comparison.json of rapt-plan compare on these runs: write the day's water it identified and "
            "cross-validated into [execution_bias] and fit the vehicle in that water.",
        ),
    ] = None,
    keep_unidentified: Annotated[
        bool,
        typer.Option(
            "--keep-unidentified",
            help="Write the file even when calibration legs were cut short: what they would have "
            "identified keeps the file's values.",
        ),
    ] = False,
) -> None:
    """Fit the vehicle's speed, turn and power terms to logs; write a mission file the planner can use."""
    from planner.review.calibrate import calibrate as run_calibrate
    from planner.review.calibrate import sidecar_path

    if not mission.is_file():
        fail(f"MISSION: {mission} does not exist; give the mission file (.toml) the runs were flown on")
    for p in logs:
        if not p.is_file():
            fail(f"LOGS: {p} does not exist; give the .mcap files of the mission's runs")
    with err.status("calibrating", spinner="dots") if err.is_terminal else nullcontext():
        try:
            result = run_calibrate(mission, logs, out_path, seed=seed, bias=bias, keep_unidentified=keep_unidentified)
        except ValueError as exc:
            fail(str(exc))
    table = Table(title=escape(f"[vehicle] calibrated from {result.runs} run(s), {result.segments} segments"))
    for col in ("parameter", "file", "calibrated", "s.e.", "unit", "identified"):
        table.add_column(col, justify="left" if col in ("parameter", "unit", "identified") else "right")
    est = result.estimate
    for n in result.fitted:
        ident = est.identified[n]
        table.add_row(
            n,
            f"{result.file_value(n):.5g}",
            f"{result.value(n):.5g}" if ident else "(kept)",
            f"{result.stderr[n]:.2g}" if ident else "-",
            result.unit(n),
            "yes" if ident else "no",
        )
    print_table(table)
    kept = result.unidentified
    if kept:
        out.print(f"not identified by these logs, file value kept: {', '.join(kept)}", highlight=False, soft_wrap=True)
        for n, need in kept.items():
            out.print(f"  to identify {n}: {need}", highlight=False, soft_wrap=True)
    b, a = result.rms_before, result.rms_after
    out.print(
        f"segment residual RMS, file vehicle -> calibrated: position {b['position_m']:.3g} -> {a['position_m']:.3g} m, "
        f"heading {b['heading_deg']:.3g} -> {a['heading_deg']:.3g} deg, energy {b['energy_wh']:.3g} -> "
        f"{a['energy_wh']:.3g} Wh",
        highlight=False,
        soft_wrap=True,
    )
    if result.water is not None:
        _print_water(result.water)
    if bias is not None:
        from sim.uuv.missionfile import load_mission as load_written

        noise = load_written(out_path).execution_noise
        line = (
            f"[execution_noise] the day's, for the re-plan's dithering: position {noise.position:.3g} m, time "
            f"{noise.time:.3g} s, battery {noise.battery:.3g} % ({noise.source})"
            if noise is not None
            else "[execution_noise] not written: the comparison fitted no execution noise (rerun rapt-plan compare)"
        )
        out.print(escape(line), highlight=False, soft_wrap=True)
    out.print(f"{out_path} and {sidecar_path(out_path)} written", highlight=False, soft_wrap=True)


def _print_water(water) -> None:
    """The day's water written into [execution_bias], and what was left out and why."""
    taken = ", ".join(f"{n} {v['value']:.5g} +- {v['stderr']:.2g}" for n, v in water.fields.items())
    out.print(
        escape(f"[execution_bias] from {water.source}: {taken or 'nothing identified and cross-validated'}"),
        highlight=False,
        soft_wrap=True,
    )
    for n, why in water.dropped.items():
        out.print(f"  {n} not written: {why}", highlight=False, soft_wrap=True)
