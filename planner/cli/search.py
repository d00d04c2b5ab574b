"""``rapt-plan search`` and ``rapt-plan study``: boundary searches of a synthetic system or a mission.

Both run one or two search methods behind a progress bar and print a table side by side
(Figure 3.12: the adaptive search against a space-filling design).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

import rapt
from planner.cli.console import fail, out, print_table, progress_bar
from planner.cli.inputs import load_mission
from rapt.metrics import quality_table
from rapt.testfunctions.registry import REFERENCE_SETTINGS, SYSTEMS, get_system, search_output_types

__all__ = ["run_search", "search", "study"]


def run_search(label: str, fn, bounds, budget: int, **kwargs):
    """``rapt.search`` behind a progress bar on stderr; bad arguments become one-line errors."""
    with progress_bar(f"{label:>6}") as bar:
        task = bar.add_task(label, total=budget, rate="")
        start = time.perf_counter()

        def progress(done: int, total: int) -> None:
            elapsed = max(time.perf_counter() - start, 1e-9)
            bar.update(task, completed=done, rate=f"{done / elapsed:,.0f} runs/s")

        try:
            found = rapt.search(fn, bounds, budget, progress=progress, **kwargs)
        except ValueError as exc:
            fail(str(exc))
        return found, time.perf_counter() - start


def _methods(method: str, baseline: str) -> list[str]:
    """The method, then the baseline unless it is 'none' or the method itself."""
    return [method] + ([baseline] if baseline not in ("none", method) else [])


def search(
    system: Annotated[str, typer.Argument(help=f"Synthetic system: {', '.join(SYSTEMS)}.")] = "plates2d",
    budget: Annotated[
        int | None, typer.Option(help="Samples to evaluate (default: the system's reference budget).")
    ] = None,
    method: Annotated[str, typer.Option(help=f"Search method: {', '.join(rapt.METHODS)}.")] = "s-ndv",
    batch_size: Annotated[int, typer.Option("--batch-size", help="Samples per batch.")] = 100,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    store: Annotated[Path | None, typer.Option(help="SQLite study store; an existing one is resumed.")] = None,
    d_eps: Annotated[float | None, typer.Option("--d-eps", help="Boundary width for the quality metrics.")] = None,
    baseline: Annotated[str, typer.Option(help="Method to compare against (or 'none').")] = "sobol",
) -> None:
    """Search a synthetic system for its performance boundaries and print the quality table."""
    if system not in SYSTEMS:
        fail(f"SYSTEM: unknown system {system!r}; choose one of: {', '.join(SYSTEMS)}")
    if baseline != "none" and baseline not in rapt.METHODS:
        fail(f"--baseline: unknown method {baseline!r}; choose one of: {', '.join(rapt.METHODS)}, none")
    ref_budget, ref_eps = REFERENCE_SETTINGS[system]
    budget = ref_budget if budget is None else budget
    d_eps = ref_eps if d_eps is None else d_eps
    if d_eps <= 0:
        fail(f"--d-eps: must be > 0, got {d_eps}")
    sut = get_system(system)
    bounds = [(0.0, 1.0)] * sut.dim
    types = search_output_types(sut)

    rows = []
    for i, m in enumerate(_methods(method, baseline)):
        study, elapsed = run_search(
            m,
            sut,
            bounds,
            budget,
            method=m,
            batch_size=batch_size,
            seed=seed,
            store=store if i == 0 else None,
            output_types=types,
        )
        q = quality_table(sut, study.X, d_eps, seed=seed)
        rows.append((m, q, elapsed, study))

    table = Table(title=f"{system}: {budget} samples, D_eps = {d_eps:g}, seed {seed}")
    for col in ("method", "precision", "coverage", "mean distance", "time (s)", "precision ×", "coverage ×"):
        table.add_column(col, justify="right" if col != "method" else "left")
    base = rows[-1][1] if len(rows) > 1 else None
    for m, q, elapsed, _ in rows:
        ratio_p = f"{q['precision'] / base['precision']:.2f}" if base and base["precision"] > 0 else "-"
        ratio_c = f"{q['coverage'] / base['coverage']:.2f}" if base and base["coverage"] > 0 else "-"
        table.add_row(
            m,
            f"{q['precision']:.1%}",
            f"{q['coverage']:.1%}",
            f"{q['mean_distance']:.4f}",
            f"{elapsed:.2f}",
            ratio_p,
            ratio_c,
        )
    print_table(table)
    study = rows[0][3]
    if study.failures:
        out.print(f"{len(study.failures)} rows failed; first reason: {study.failures[0]}", soft_wrap=True)
    if store is not None:
        out.print(f"study stored in {store} ({study.n_evaluated} rows)", soft_wrap=True, highlight=False)


def study(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML), e.g. examples/range2017.toml.")],
    budget: Annotated[int, typer.Option(help="Scenarios to simulate.")] = 3000,
    method: Annotated[str, typer.Option(help=f"Search method: {', '.join(rapt.METHODS)}.")] = "s-ndv",
    batch_size: Annotated[int, typer.Option("--batch-size", help="Scenarios per batch.")] = 500,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    store: Annotated[Path | None, typer.Option(help="SQLite study store; an existing one is resumed.")] = None,
    stochastic: Annotated[bool, typer.Option(help="Navigation drift and current perturbations on.")] = False,
    baseline: Annotated[str, typer.Option(help="Method to compare against (or 'none').")] = "sobol",
) -> None:
    """Search a mission's scenarios for performance boundaries; print modes and boundary types."""
    from planner.plan.mission_search import ROOT_OUTPUT_TYPES, ModeSearch, root_scores
    from sim.uuv.scoring import MODE_NAMES

    if baseline != "none" and baseline not in rapt.METHODS:
        fail(f"--baseline: unknown method {baseline!r}; choose one of: {', '.join(rapt.METHODS)}, none")
    mission = load_mission(mission_file)
    scores = root_scores(mission, seed=seed, stochastic=stochastic)
    results = []
    for i, m in enumerate(_methods(method, baseline)):
        found, elapsed = run_search(
            m,
            scores,
            mission.space,
            budget,
            method=m,
            batch_size=batch_size,
            seed=seed,
            store=store if i == 0 else None,
            output_types=ROOT_OUTPUT_TYPES,
        )
        results.append(ModeSearch.of(m, found, elapsed))

    table = Table(title=f"{mission.name}: {budget} scenarios ({mission.dim}-D), seed {seed}")
    table.add_column("", justify="left")
    for r in results:
        table.add_column(r.method, justify="right")
    table.add_row("valid runs", *[f"{len(r.found.X):,}" for r in results])
    table.add_row("invalid scenarios", *[f"{len(r.found.X_failed):,}" for r in results])
    for k, name in enumerate(MODE_NAMES):
        table.add_row(f"mode {name}", *[f"{r.mode_share(k):.1%}" for r in results])
    for a, b in sorted(set().union(*(r.boundary_types() for r in results))):
        table.add_row(
            f"boundary {MODE_NAMES[a]}/{MODE_NAMES[b]}",
            *[f"{r.boundary_count(a, b):,} ({r.boundary_count(a, b) / (r.n_pairs or 1):.0%})" for r in results],
        )
    table.add_row(
        "median pair distance", *["-" if (d := r.median_pair_distance()) is None else f"{d:.3f}" for r in results]
    )
    table.add_row("time (s)", *[f"{r.seconds:.1f}" for r in results])
    print_table(table)
    if store is not None:
        out.print(
            f"study stored in {store} ({results[0].found.n_evaluated} scenarios)", soft_wrap=True, highlight=False
        )
