"""``rapt-plan generate``: search a mission, choose boundary pairs, dither them and write a field plan."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from planner.cli.console import err, fail, out, print_table, progress_bar
from planner.cli.inputs import load_mission

__all__ = ["generate", "summary_table"]


def summary_table(plan: dict, title: str) -> Table:
    """Per pair: its sub-boundary and modes, distance, P(predicted outcome) of each side and flown variant, verdict
    (:func:`straddle_line` gives the chance that both flown sides show their outcomes)."""
    table = Table(title=title)
    for col in ("pair", "sub-boundary", "modes", "distance", "P a / b", "variant P", "verdict"):
        table.add_column(col, justify="left" if col in ("sub-boundary", "verdict") else "right")

    def pct(values) -> str:
        return " / ".join("-" if v is None else f"{v:.0%}" for v in values or (None, None))

    for p in plan["pairs"]:
        table.add_row(
            str(p["id"]),
            ", ".join(p["elements"]),
            " / ".join(p["modes"]),
            f"{p['distance']:.3f}",
            pct(p.get("p_predicted")),
            pct(p.get("variant_p_predicted")),
            p.get("verdict", "-"),
        )
    return table


def straddle_line(plan: dict) -> str | None:
    """One line: each pair's P(straddle), the chance that both flown sides show their predicted outcomes (None
    undithered)."""
    from planner.plan.pair_shifts import shift_note

    shown = [f"pair {p['id']} {p['p_straddle']:.0%}" for p in plan["pairs"] if p.get("p_straddle") is not None]
    if not shown:
        return None
    moved = [f"pair {p['id']} {shift_note(p['shifted'])}" for p in plan["pairs"] if p.get("shifted")]
    return "P(straddle), both flown sides as predicted: " + ", ".join(shown) + "".join(f"; {m}" for m in moved)


def _print_lines(plan: dict) -> None:
    """Below the table: each pair's P(straddle), the day the plan was made for, what no run reaches."""
    from planner.plan.planned_for import summary_lines
    from planner.plan.unreached import unreached_line

    lines = [straddle_line(plan), *summary_lines(plan["mission"].get("planned_for"))]
    lines.append(unreached_line(plan["study"].get("unreached")))
    for line in lines:
        if line is not None:
            out.print(escape(line), soft_wrap=True, highlight=False)


def generate(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Directory for plan.json and the per-scenario files.")],
    budget: Annotated[int, typer.Option(help="Runs in the search.")] = 3000,
    pairs: Annotated[int, typer.Option(help="Boundary pairs in the plan.")] = 5,
    global_fraction: Annotated[float, typer.Option(help="Share of the budget for the space-filling start.")] = 0.2,
    dithers: Annotated[int, typer.Option(help="Stochastic dither runs per pair.")] = 2000,
    dither_sigma: Annotated[
        str | None,
        typer.Option(
            "--dither-sigma",
            help="Expected execution noise the dithers model: position=M,time=S,battery=PCT "
            "(metres, seconds, percent of capacity; kinds left out keep their default) or one "
            "unit-cube sigma for every parameter, e.g. 0.02. Default: the mission file's "
            "[execution_noise] (the day's, as rapt-plan calibrate --bias writes it), else "
            "position=10,time=30,battery=1.",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    batch_size: Annotated[
        int | None,
        typer.Option("--batch-size", help="Runs per search batch (default: about 40 batches of 250 to 5,000)."),
    ] = None,
    resume: Annotated[
        bool,
        typer.Option(help="Continue the study stored in OUT/study.db (or start it: nothing evaluated is run again)."),
    ] = False,
    executor: Annotated[str, typer.Option(help="local, processes or dask://host:port.")] = "local",
    refine: Annotated[
        bool,
        typer.Option(
            "--refine",
            help="Sharpen candidate pairs with a focused search on their own sub-scores; ship only sharp ones.",
        ),
    ] = False,
    refine_runs: Annotated[
        int,
        typer.Option(
            "--refine-runs",
            help="Runs per candidate pair of --refine (twice --pairs candidates; counted in --budget).",
        ),
    ] = 160,
    surrogate: Annotated[
        Path | None,
        typer.Option(
            "--surrogate",
            help="Search with a learned surrogate of the autonomy (section 6.2.3): load this .npz "
            "(trained for this mission), or train one (200 annotated + 50 held-out expert runs) "
            "and save it here; the expert then confirms the candidate pairs.",
        ),
    ] = None,
    confirm_runs: Annotated[
        int,
        typer.Option(
            "--confirm-runs",
            help="Budget of expert runs that look for the expert's own boundary near the surrogate's "
            "candidate pairs (at least two per pair).",
        ),
    ] = 100,
    noisy_search: Annotated[
        bool,
        typer.Option(
            "--noisy-search",
            help="Search the stochastic simulator (navigation drift, current perturbations; seeded by --seed) "
            "and steer on the closest approaches, mission time and energy as well as the modes (section "
            "4.2.3): under noise pass/fail blurs, while continuous metrics jump where the autonomy's "
            "decision changes. Pairs still come from the modes; the study is stored in OUT/study-noisy.db.",
        ),
    ] = False,
) -> None:
    """Search a mission, choose boundary pairs, dither them and write a field plan."""
    from planner.plan.generate import GenerateConfig, make_executor
    from planner.plan.generate import generate as run_generate
    from planner.plan.noisy_search import NOISY_STORE

    mission = load_mission(mission_file)
    store = out_dir / (NOISY_STORE if noisy_search else "study.db" if surrogate is None else "study-surrogate.db")
    if store.exists() and not resume:
        fail(f"--out: {store} already holds a study; add --resume to continue it or choose another directory")
    cfg = GenerateConfig(
        budget=budget,
        pairs=pairs,
        global_fraction=global_fraction,
        seed=seed,
        batch_size=batch_size,
        dithers=dithers,
        dither_sigma=dither_sigma,
        store=store,
        refine=refine_runs if refine else 0,
        confirm_runs=confirm_runs,
        surrogate_file=str(surrogate or ""),
        noisy_search=noisy_search,
    )
    try:
        cfg.check()
        cfg.noise(mission).sigmas(mission)  # a noise wider than a parameter's range fails before the search
    except ValueError as exc:
        fail(str(exc))
    if surrogate is not None:
        from planner.plan.surrogate import load_or_train

        try:
            if not surrogate.exists():
                err.print(f"training a surrogate of {mission.name}'s autonomy into {surrogate} ...")
            cfg.surrogate, _ = load_or_train(surrogate, mission, seed=seed)
        except (ValueError, OSError) as exc:
            fail(f"--surrogate: {exc}")
    try:
        cfg.executor, close_executor = make_executor(executor)
    except (ValueError, OSError) as exc:
        fail(str(exc))
    out_dir.mkdir(parents=True, exist_ok=True)
    with progress_bar("{task.description:>8}") as bar:
        tasks: dict = {}
        start = time.perf_counter()

        def progress(stage: str, done: int, total: int, detail: str) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total, rate="")
            if stage == "search":
                detail = f"{done / max(time.perf_counter() - start, 1e-9):,.0f} runs/s, {detail}"
            bar.update(tasks[stage], completed=done, rate=detail)

        try:
            plan = run_generate(mission, mission_file, out_dir, cfg, progress)
        except (ValueError, RuntimeError) as exc:
            fail(str(exc))
        finally:
            close_executor()
    print_table(summary_table(plan, f"{mission.name}: field plan in {out_dir}"))
    _print_lines(plan)
    for p in plan["pairs"]:
        if p.get("reason"):
            out.print(f"pair {p['id']} is fragile: {p['reason']}", soft_wrap=True, highlight=False)
    out.print(
        f"{plan['study']['valid_runs']:,} valid runs; plan.json and {len(plan['scenarios'])} scenarios "
        f"(.plan, .waypoints, .geojson) written",
        soft_wrap=True,
        highlight=False,
    )
    if surrogate is not None:
        s = plan["study"]["surrogate"]
        out.print(
            f"surrogate search: the expert confirmed {s['confirmed']} of {s['examined']} candidate pairs examined "
            f"({s['share_confirmed']:.0%}; {s['candidates']} offered); expert runs: {s['expert_runs']['training']} "
            f"training + {s['expert_runs']['confirmation']} confirmation (budget {s['confirm_budget']})",
            soft_wrap=True,
            highlight=False,
        )
