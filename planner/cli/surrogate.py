"""``rapt-plan surrogate``: train a surrogate of a mission's autonomy and print each update's progress."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from planner.cli.console import err, fail, out, print_table
from planner.cli.inputs import load_mission

__all__ = ["surrogate"]


def surrogate(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    out_file: Annotated[Path, typer.Option("--out", help="Surrogate file to write (.npz).")],
    method: Annotated[
        str,
        typer.Option(
            help="qdagger (Algorithm 9: re-mines the aggregate), qdagger-new (trims only each new set), dagger or supervised."
        ),
    ] = "qdagger",
    quantile: Annotated[
        float,
        typer.Option(
            help="Q-DAgger: keep the states predicted worse than this quantile of the aggregate "
            "(qdagger-new: of each new set; 0.5, 0.75)."
        ),
    ] = 0.5,
    runs: Annotated[int, typer.Option(help="Annotated expert runs in all.")] = 200,
    runs_per_iteration: Annotated[int, typer.Option("--runs-per-iteration", help="New runs per update.")] = 10,
    epochs: Annotated[int, typer.Option(help="Training epochs per update (warm-started).")] = 30,
    mixing: Annotated[
        float,
        typer.Option(
            help="Update i's runs obey the expert on a share mixing**i of their steps "
            "(DAgger's beta; 0: the learner flies every step)."
        ),
    ] = 0.5,
    select_runs: Annotated[
        int,
        typer.Option(
            "--select-runs",
            help="Held-out expert runs that choose which update's policy to keep (directed: pairs at its "
            "boundary candidates, the most expert boundary pairs reproduced per type; uniform: the best mode "
            "accuracy; 0: the last) and its goal threshold.",
        ),
    ] = 50,
    observation: Annotated[
        str,
        typer.Option(
            help="What the learner observes: contacts (the expert's remembered sonar contacts) or scan "
            "(a 360-degree scan, no memory: section 6.5.3)."
        ),
    ] = "contacts",
    directed: Annotated[
        bool,
        typer.Option(
            "--directed/--uniform",
            help="Annotate at the learner's boundary candidates from the third update on (or draw uniformly).",
        ),
    ] = True,
    validate: Annotated[
        int, typer.Option(help="Sobol scenarios to measure mode accuracy on after each update (0: none).")
    ] = 256,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
) -> None:
    """Train a surrogate of a mission's back-seat autonomy by imitation learning (chapter 6)."""
    from planner.plan.surrogate import ModeValidation, train_surrogate
    from sim.uuv.imitation.features import OBSERVATIONS

    mission = load_mission(mission_file)
    if out_file.suffix != ".npz":
        fail(f"--out: a surrogate file ends in .npz, got {out_file}")
    if validate < 0:
        fail(f"--validate: expected a number of scenarios >= 0, got {validate}")
    if observation not in OBSERVATIONS:
        fail(f"--observation: expected {' or '.join(OBSERVATIONS)}, got {observation!r}")
    accuracy = ModeValidation(mission, validate, seed, observation) if validate else None
    table = Table(title=f"{mission.name}: {method} imitation of the autonomy")
    for col in ("iteration", "expert runs", "samples", "fit (s)", "train MSE") + (
        ("mode accuracy",) if validate else ()
    ):
        table.add_column(col, justify="right")

    def on_iteration(rec, policy):
        row = [str(rec.iteration), str(rec.runs), f"{rec.samples:,}", f"{rec.fit_s:.1f}", f"{rec.loss:.4f}"]
        if accuracy is not None:
            row.append(f"{accuracy(policy):.1%}")
        table.add_row(*row)
        err.print(" ".join(row), highlight=False)

    try:
        sur = train_surrogate(
            mission,
            method=method,
            quantile=quantile,
            runs=runs,
            runs_per_iteration=runs_per_iteration,
            epochs=epochs,
            mixing=mixing,
            select_runs=select_runs,
            seed=seed,
            on_iteration=on_iteration,
            observation=observation,
            directed=directed,
        )
    except ValueError as exc:
        fail(f"--{str(exc)}" if str(exc).split(":")[0] in ("method", "quantile", "epochs") else str(exc))
    sur.save(out_file)
    print_table(table)
    t = sur.training
    judged = (
        f"{t['selection']:.1%} of the expert's {t['held_out_boundary_pairs']} held-out boundary pairs, per type"
        if t["directed"] and t["held_out_boundary_pairs"]
        else "no held-out boundary pair: on mode accuracy"
        if t["directed"]
        else f"{t['selection']:.1%} mode accuracy"
    )
    kept = (
        f"update {t['chosen_iteration']} kept ({judged} on {t['select_runs']} held-out runs), "
        f"goal threshold {sur.goal_threshold:+.1f}"
        if t["select_runs"]
        else "last update kept"
    )
    out.print(
        f"surrogate of {mission.name} written to {out_file} ({t['runs']} expert runs: {t['annotated_runs']} "
        f"annotated + {t['select_runs']} held out; {kept}; {sur.spec.size} features)",
        soft_wrap=True,
        highlight=False,
    )
