"""``rapt-plan next``: the afternoon's next run, from the plan and the day's logs so far."""

from __future__ import annotations

import json
from contextlib import nullcontext
from pathlib import Path
from typing import Annotated

import typer

from planner.cli.confirmation_table import confirmation_rich_table
from planner.cli.console import err, fail, out, print_table

__all__ = ["next_run"]


def next_run(
    plan_dir: Annotated[Path, typer.Argument(help="Plan directory (or its plan.json) the afternoon flies.")],
    logs: Annotated[
        list[Path] | None,
        typer.Argument(help="MCAP logs of today's runs of the plan so far (any scenarios, repeats allowed)."),
    ] = None,
    runs_left: Annotated[
        int, typer.Option("--runs-left", help="Runs the day has left, this one included (0: the day is done).")
    ] = ...,  # type: ignore[assignment]
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    as_json: Annotated[
        bool, typer.Option("--json", help="End with one JSON line: the next run, its reason, each pair's status.")
    ] = False,
) -> None:
    """Name the run that most raises the boundaries confirmed by the day's end: a side, a side again, a side moved, or stop."""
    from planner.conduct.next_run import conduct
    from rapt.errors import RaptError

    with err.status("next", spinner="dots") if err.is_terminal else nullcontext() as status:

        def progress(stage: str) -> None:
            if status is not None:
                status.update(stage)

        try:
            result = conduct(plan_dir, logs or [], runs_left, seed=seed, progress=progress)
        except (RaptError, ValueError) as exc:
            fail(str(exc))
    p_confirm = {p["id"]: p["p_confirm"] for p in result["pairs"]}
    print_table(confirmation_rich_table(result["confirmation"], p_confirm))
    lost = [str(p["id"]) for p in result["pairs"] if p["status"] == "lost"]
    if lost:
        out.print(f"lost (no run left can confirm them): pair {', '.join(lost)}", highlight=False, soft_wrap=True)
    nxt = result["next"]
    out.print(
        f"next: {nxt['scenario']}: {result['reason']}" if nxt else result["reason"], highlight=False, soft_wrap=True
    )
    if nxt:
        out.print(
            f"fly it: rapt-plan run {nxt['plan']} --scenario {nxt['scenario']} --log run{result['logs'] + 1}_{nxt['scenario']}.mcap",
            highlight=False,
            soft_wrap=True,
        )
    if as_json:
        print(json.dumps({k: result[k] for k in ("next", "reason", "pairs")}))
