"""``rapt-plan check LOG.mcap``: the automatic checks of a run's log, on their own (``compare`` runs them too)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from planner.cli.console import fail, out, print_table

__all__ = ["check", "checks_table"]


def checks_table(runs: list[tuple[str, list[dict]]], *, all_checks: bool = False) -> Table | None:
    """Per run, its checks (only those that did not pass unless ``all_checks``): verdict, when, value against
    threshold, why. None when there is nothing to show."""
    rows = [(name, c) for name, checks in runs for c in checks if all_checks or c["verdict"] != "pass"]
    if not rows:
        return None
    table = Table(title="run checks" if all_checks else "run checks that did not pass")
    for col in ("log", "check", "verdict", "at (s)", "value / threshold", "why"):
        table.add_column(col, justify="right" if col == "at (s)" else "left")
    style = {"fail": "bold red", "warn": "yellow", "unknown": "yellow", "pass": "green"}
    for name, c in rows:
        at = "-" if c.get("time_s") is None else f"{c['time_s']:.1f}"
        value = "-" if c.get("value") is None else f"{_short(c['value'])} / {_short(c.get('threshold'))}"
        verdict = f"[{style[c['verdict']]}]{c['verdict']}[/]"
        table.add_row(escape(name), c["name"], verdict, at, escape(value), escape(c["reason"]))
    return table


def _short(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def check(
    logs: Annotated[list[Path], typer.Argument(help="MCAP logs of runs (rapt-plan run --log, or rapt-plan log).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the checks as JSON instead of a table.")] = False,
) -> None:
    """Check that each run was sound: estimator, position, link, set-points, thrusters, depth, pack, failsafes.

    Exit code 1 when a check failed (such a run does not count towards compare's bias fit
    unless --keep-failed), 0 otherwise; a check that cannot judge a damaged log says unknown.
    """
    from planner.review.logs import read_run
    from planner.review.run_checks import verdict_of

    runs = []
    for p in logs:
        if not p.is_file():
            fail(f"LOGS: {p} does not exist; give the .mcap file of a run")
        try:
            runs.append((p.name, read_run(p).checks))
        except ValueError as exc:
            fail(str(exc))
    if as_json:
        out.print_json(json.dumps({name: checks for name, checks in runs}))
    else:
        table = checks_table(runs, all_checks=True)
        assert table is not None, "every log has its checks"
        print_table(table)
    if any(verdict_of(checks) == "fail" for _, checks in runs):
        raise typer.Exit(code=1)
