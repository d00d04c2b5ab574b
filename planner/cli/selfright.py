"""``rapt-plan selfright``: a ground robot's self-righting transition graph (chapter 5), written to a directory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from planner.cli.console import fail
from planner.cli.console import out as console

__all__ = ["selfright"]


def selfright(
    robot_file: Annotated[
        Path,
        typer.Argument(
            metavar="ROBOT_FILE",
            help="Robot file, TOML or URDF (by suffix: .toml, .urdf), e.g. examples/robots/1dof.toml.",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", help="Directory for graph.json, graph.graphml, states.png, report.md.")],
    slope: Annotated[
        float | None, typer.Option(help="Ground slope in degrees (default: the robot file's, else 0).")
    ] = None,
    budget: Annotated[
        int, typer.Option(help="Queries to the stability function (a planar robot's last hull may add a few faces).")
    ] = 1000,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    batch_size: Annotated[int, typer.Option("--batch-size", help="Queries per batch.")] = 50,
    r_min: Annotated[float, typer.Option("--r-min", help="Boundary resolution, degrees (search ends below it).")] = 1.0,
    r_max: Annotated[float, typer.Option("--r-max", help="Interior resolution, degrees.")] = 10.0,
    refine: Annotated[
        float,
        typer.Option(
            "--refine",
            help="Share of the budget kept to bisect each transition's boundary pair below --r-min (0: off).",
        ),
    ] = 0.1,
    outcomes: Annotated[
        bool,
        typer.Option(
            "--outcomes",
            help="Also steer the search by where states tip to "
            "(finds stable islands narrower than a coarse --r-max such as 45; costs at a fine one).",
        ),
    ] = False,
    max_edge: Annotated[
        float | None,
        typer.Option(
            "--max-edge", help="Gabriel graph's longest edge, degrees (default: 2 to 4 x --r-max, by sample density)."
        ),
    ] = None,
) -> None:
    """Self-righting transition graph of a ground robot by manifold-constrained adaptive sampling (chapter 5)."""
    import numpy as np

    from planner.selfright import adaptive_study, analyse, write_outputs
    from sim.robots import RobotFileError, load_robot

    try:
        robot = load_robot(robot_file)
    except RobotFileError as exc:
        fail(str(exc))
    slope = robot.slope if slope is None else slope
    if not 0 <= slope < 90:
        fail(f"--slope: expected degrees in [0, 90), got {slope:g}")
    if budget < 10:
        fail(f"--budget: expected at least 10 queries, got {budget}")
    if batch_size < 1:
        fail(f"--batch-size: expected a positive number of queries, got {batch_size}")
    if not 0 < r_min <= r_max:
        fail(f"--r-min/--r-max: expected 0 < r_min <= r_max degrees, got {r_min:g} and {r_max:g}")
    if not 0 <= refine < 1:
        fail(f"--refine: expected a share of the budget in [0, 1), got {refine:g}")
    if max_edge is not None and max_edge <= 0:
        fail(f"--max-edge: expected degrees > 0, got {max_edge:g}")
    if out.exists() and not out.is_dir():
        fail(f"--out: {out} is a file; give a directory")
    study = adaptive_study(
        robot,
        slope,
        budget,
        seed=seed,
        batch_size=batch_size,
        r_min_deg=r_min,
        r_max_deg=r_max,
        refine=refine,
        outcomes=outcomes,
    )
    result = analyse(study, max_edge=None if max_edge is None else np.radians(max_edge))
    doc = write_outputs(study, result, out)
    energy = doc["mean_energy_to_home_J"]
    console.print(
        f"{robot.name} on a {slope:g}° slope: {study.queries:,} queries"
        f"{' (resolution reached)' if study.stopped_by_resolution else ''}, "
        f"{len(doc['nodes'])} nodes, {len(doc['edges'])} transitions; "
        f"self-rightable {doc['self_rightable_fraction']:.1%}, mean energy to home "
        f"{'n/a' if energy is None else f'{energy:.2f} J'}; wrote {out}/graph.json, graph.graphml, states.png, report.md",
        soft_wrap=True,
        highlight=False,
    )
