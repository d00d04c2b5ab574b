"""``rapt-plan compare``: run logs against their plan, printed as tables and flagged pairs."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from planner.cli.check import checks_table
from planner.cli.confirmation_table import confirmation_rich_table
from planner.cli.console import err, fail, out, print_table

__all__ = ["compare"]


def compare(
    plan_dir: Annotated[Path, typer.Argument(help="Plan directory (or its plan.json) from rapt-plan generate.")],
    logs: Annotated[list[Path], typer.Argument(help="MCAP logs of the plan's runs (SIL or the real vehicle).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Directory for comparison.json and comparison.html.")] = Path(
        "comparison"
    ),
    calibrated: Annotated[
        Path | None,
        typer.Option(
            help="A calibrated mission file (rapt-plan calibrate): predict with its vehicle, then fit the bias."
        ),
    ] = None,
    dithers: Annotated[int, typer.Option(help="Stochastic runs checking each adjusted scenario (0: none).")] = 20,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    draws: Annotated[
        int,
        typer.Option(
            help="Monte-Carlo runs per scenario of each forecast (the plan's execution noise, with and "
            "without draws of the fitted bias)."
        ),
    ] = 100,
    bootstrap: Annotated[
        int,
        typer.Option(
            help="Resampling of the bias's standard errors: block-bootstrap refits with fewer than 6 logs, "
            "a delete-one-log jackknife with more (0: analytic standard errors only, faster)."
        ),
    ] = 20,
    fit: Annotated[
        str | None,
        typer.Option(
            help="Bias parameters to fit, comma-separated (default: all of "
            "speed, current_scale, current_offset, current_cross, heading, battery, "
            "start_time)."
        ),
    ] = None,
    keep_failed: Annotated[
        bool,
        typer.Option(
            "--keep-failed",
            help="Count runs whose automatic checks failed in the bias fit (by default they are shown but not "
            "counted).",
        ),
    ] = False,
) -> None:
    """Compare run logs with the plan: predicted vs observed, run checks, execution bias, re-plan."""
    from planner.review.runs import CompareConfig

    names = _bias_names(fit)
    _check_options(dithers, bootstrap, logs)
    if draws < 1:
        fail(f"--draws: expected a number of runs >= 1, got {draws}")
    plant = None
    if calibrated is not None:
        plant = _calibrated_vehicle(plan_dir, calibrated)
    config = CompareConfig(
        dithers=dithers, seed=seed, fit=names, plant=plant, bootstrap=bootstrap, draws=draws, keep_failed=keep_failed
    )
    result = _run_compare(plan_dir, logs, out_dir, config)
    _warn_lost(result)
    print_table(_scenario_table(result))
    checks = checks_table([(Path(lg["path"]).name, lg["checks"]) for lg in result["logs"]])
    if checks is not None:
        print_table(checks)
    excluded = result["run_checks"]["excluded_from_bias_fit"]
    if excluded:
        err.print(
            f"[yellow]warning:[/] not counted in the bias fit (a check failed; --keep-failed counts them): "
            f"{', '.join(excluded)}",
            highlight=False,
            soft_wrap=True,
        )
    print_table(_bias_table(result))
    _print_day_bias(result)
    _print_agreement(result)
    print_table(_forecast_table(result))
    print_table(_brier_table(result))
    print_table(_reliability_table(result))
    noise = result["forecast"].get("day_noise") or {}
    if noise.get("note"):
        out.print(f"day's execution noise: {noise['note']}", highlight=False, soft_wrap=True)
    print_table(confirmation_rich_table(result["confirmation"]))
    _print_flagged(result)
    overlays = len(result.get("overlays", {}))
    out.print(
        f"comparison.json, comparison.html and {overlays} Foxglove overlay(s) (overlay_*.mcap) written to {out_dir}",
        highlight=False,
        soft_wrap=True,
    )


def _bias_names(fit: str | None) -> tuple[str, ...]:
    """The bias parameters --fit names (all of them without it); a one-line error for an unknown one."""
    from sim.uuv.bias import BIAS_NAMES

    names = BIAS_NAMES
    if fit is not None:
        names = tuple(n.strip() for n in fit.split(",") if n.strip())
        bad = [n for n in names if n not in BIAS_NAMES]
        if bad or not names:
            fail(f"--fit: unknown bias parameter {bad[0] if bad else fit!r}; choose from {', '.join(BIAS_NAMES)}")
    return names


def _check_options(dithers: int, bootstrap: int, logs: list[Path]) -> None:
    """A one-line error for a negative count or a log that is not there."""
    if dithers < 0:
        fail(f"--dithers: expected a number of runs >= 0, got {dithers}")
    if bootstrap < 0:
        fail(f"--bootstrap: expected a number of refits >= 0, got {bootstrap}")
    for p in logs:
        if not p.is_file():
            fail(f"LOGS: {p} does not exist; give the .mcap files of the plan's runs")


def _run_compare(plan_dir: Path, logs: list[Path], out_dir: Path, config) -> dict:
    """:func:`planner.review.compare.compare` under a spinner naming its stage (on a terminal)."""
    from planner.review.compare import compare as run_compare

    with err.status("comparing", spinner="dots") if err.is_terminal else nullcontext() as status:

        def progress(stage: str) -> None:
            if status is not None:
                status.update(stage)

        try:
            return run_compare(plan_dir, logs, out_dir, config, progress)
        except ValueError as exc:
            fail(str(exc))


def _warn_lost(result: dict) -> None:
    """A warning per log for what it lost: damaged parts, frames lost on the way."""
    for lg in result["logs"]:
        for problem in lg["lost"]:
            err.print(f"[yellow]warning:[/] {Path(lg['path']).name}: {problem}", highlight=False, soft_wrap=True)
        losses = lg.get("losses")
        if isinstance(losses, dict) and losses.get("total"):
            err.print(
                f"[yellow]warning:[/] {Path(lg['path']).name}: {losses['total']:,} frame(s) lost on the way to the log "
                f"(link {losses.get('link_lost')}, bus {losses.get('bus_lost')}, write errors {losses.get('write_errors')})",
                highlight=False,
                soft_wrap=True,
            )


def _scenario_table(result: dict) -> Table:
    """Per logged run: predicted, observed and corrected modes, path errors, frames lost."""
    table = Table(
        title=f"{result['plan']['mission']}: {len(result['scenarios'])} run(s) against plan {result['plan']['id']}"
    )
    cols = (
        "scenario",
        "predicted",
        "observed",
        "corrected",
        "path error (m)",
        "corrected (m)",
        "frames lost",
        "checks",
    )
    for col in cols:
        table.add_column(col, justify="left" if col in ("scenario", "checks") else "right")
    for r in result["scenarios"]:
        pe, pc = r["path_error_m"], r["path_error_corrected_m"]
        table.add_row(
            r["id"],
            r["predicted_mode"],
            r["observed_mode"] or "end not logged",
            r["corrected_mode"],
            "-" if pe is None else f"{pe:.1f}",
            "-" if pc is None else f"{pc:.1f}",
            str(r.get("frames_lost", "unknown")),
            r.get("checks", "-"),
        )
    return table


def _bias_table(result: dict) -> Table:
    """The fitted execution bias: estimate, standard error, prior and whether the logs identify it."""
    bias = Table(title="execution bias (MAP fit to all logs; unidentified parameters stay neutral)")
    for col in ("parameter", "estimate", "std. error", "prior", "identified", "unit"):
        bias.add_column(col, justify="left" if col in ("parameter", "unit", "identified") else "right")
    units = result["bias_fit"]["units"]
    for n, v in result["bias"].items():
        prior = v.get("prior")
        bias.add_row(
            n,
            f"{v['estimate']:.4g}",
            f"{v['stderr']:.2g}",
            "-" if prior is None else f"{prior['centre']:g} ± {prior['sd']:g}",
            "yes" if v["identified"] else "no (neutral)",
            units[n],
        )
    return bias


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.0%}"


def _print_agreement(result: dict) -> None:
    """Held-out and overall mode agreement, and whether the correction is used."""
    ag = result["mode_agreement"]
    cv = result["cross_validation"]
    held = cv["held_out_mode_agreement"]
    out.print(
        f"held-out (leave one log out) mode agreement: {_pct(held['uncorrected'])} uncorrected, "
        f"{_pct(held['corrected'])} corrected ({held['runs']} runs)",
        highlight=False,
        soft_wrap=True,
    )
    out.print(result["correction"]["note"], highlight=False, soft_wrap=True)
    out.print(
        f"mode agreement: {_pct(ag['uncorrected'])} as planned, {_pct(ag['corrected'])} with the correction used "
        f"({ag['scenarios']} scenarios with a logged end)",
        highlight=False,
        soft_wrap=True,
    )


def _prob(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _forecast_table(result: dict) -> Table:
    """Per logged run: the deterministic (corrected) mode beside P(observed mode) under each forecast."""
    fc = result["forecast"]
    table = Table(title=f"P(observed mode), {fc['draws']} runs per scenario")
    for col in ("scenario", "observed", "det.", "noise", "bias+noise"):
        table.add_column(col, justify="left" if col == "scenario" else "right")
    for r in result["scenarios"]:
        p = r["forecast"]["p_observed_mode"]
        table.add_row(
            r["id"],
            r["observed_mode"] or "-",
            r["forecast"]["deterministic"]["corrected"],
            _prob(p["noise"]),
            _prob(p["bias_noise"]),
        )
    return table


def _brier_table(result: dict) -> Table:
    """The day's Brier scores (lower is better): the deterministic predictions against the forecasts."""
    fc = result["forecast"]
    b = fc["brier"]
    table = Table(title=f"Brier score, {b['runs']} runs (0: perfect)")
    for col in ("prediction", "modes", "held"):
        table.add_column(col, justify="left" if col == "prediction" else "right")
    used = "bias_noise" if fc["corrected_is"] == "bias_noise" else "noise"
    rows = [
        ("deterministic_uncorrected", "as planned"),
        ("deterministic_corrected", "corrected"),
        ("noise", "noise"),
        ("bias_noise", "bias+noise"),
    ]
    if "corrected_assumed_noise" in b:
        rows.append(("corrected_assumed_noise", "corrected, plan's assumed noise"))
    for key, label in rows:
        table.add_row(label + (" (used)" if key == used else ""), _prob(b[key]["mode"]), _prob(b[key]["held"]))
    return table


def _reliability_table(result: dict) -> Table:
    """The corrected forecast's reliability: per bin of P(the predicted mode held), the runs and the share held."""
    fc = result["forecast"]
    table = Table(title="Reliability of the corrected forecast (P held against the share held)")
    for col in ("P held", "runs", "mean P", "held"):
        table.add_column(col, justify="right")
    for row in fc.get("reliability", []):
        table.add_row(
            f"{row['p_low']:.1f}-{row['p_high']:.1f}", str(row["runs"]), _prob(row["mean_p"]), _prob(row["held"])
        )
    return table


def _print_flagged(result: dict) -> None:
    """The pairs the bias moved off their boundary, and the adjusted scenario proposed for each side."""
    flagged = [p for p in result["pairs"] if p["flagged"]]
    for p in flagged:
        out.print(
            f"pair {p['id']} ({' / '.join(p['scenarios'])}) flagged: {p['reason']}", highlight=False, soft_wrap=True
        )
    for q in result["proposals"]:
        if q["found"]:
            mv = q["moved"]
            out.print(
                f"  propose {q['id']}: {mv['parameter']} {mv['from']:.6g} -> {mv['to']:.6g} "
                f"(under the bias: {q['predicted_mode_under_bias']})"
                if isinstance(mv["from"], float)
                else f"  propose {q['id']}: {mv['parameter']} {mv['from']} -> {mv['to']}",
                highlight=False,
                soft_wrap=True,
            )
        else:
            out.print(f"  {q['variant_of']}: {q['note']}", highlight=False, soft_wrap=True)


def _calibrated_vehicle(plan_dir: Path, calibrated: Path):
    """The vehicle of a calibrated mission file of the plan's mission; a one-line error otherwise."""
    import sim.uuv
    from planner.common.plans import load_plan

    if not calibrated.is_file():
        fail(f"--calibrated: {calibrated} does not exist; give the file rapt-plan calibrate wrote")
    try:
        mission = sim.uuv.load_mission(calibrated)
        plan_mission = load_plan(plan_dir).mission
    except ValueError as exc:
        fail(str(exc))
    if mission.name != plan_mission.name:
        fail(
            f"--calibrated: {calibrated} is mission {mission.name!r}, but the plan is for {plan_mission.name!r}; "
            "calibrate from the plan's own mission file"
        )
    return mission.vehicle


def _print_day_bias(result: dict) -> None:
    """When the plan was made for a day's bias: the fit is relative to it; say so, with the totals."""
    day = result.get("day_bias") or {}
    if not day.get("relative"):
        return
    from sim.uuv.bias import NEUTRAL

    def changed(values: dict) -> str:
        return ", ".join(f"{n}={v:.4g}" for n, v in values.items() if v != NEUTRAL[n]) or "none"

    out.print(
        f"the plan was made for the day's bias {changed(day['assumed'])}; the bias above is relative to it. "
        f"Total fitted: {changed(day['fitted_total'])}; total used: {changed(day['correction_total'])}",
        highlight=False,
        soft_wrap=True,
    )
