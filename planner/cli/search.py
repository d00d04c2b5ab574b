"""``rapt-plan search`` and ``rapt-plan study``: boundary searches of a synthetic system or a mission.

Both run one or two search methods behind a progress bar and print a table side by side
(Figure 3.12: the adaptive search against a space-filling design).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

import rapt
from planner.cli.console import err, fail, out
from planner.cli.inputs import load_mission
from rapt.metrics import quality_table
from rapt.testfunctions import REFERENCE_SETTINGS, SYSTEMS, get_system, search_output_types

__all__ = ["run_search", "search", "study"]


def run_search(label: str, fn, bounds, budget: int, **kwargs):
    """``rapt.search`` behind a progress bar on stderr; bad arguments become one-line errors."""
    with Progress(TextColumn(f"{label:>6}"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[rate]}"),
                  TimeElapsedColumn(), console=err, transient=True, disable=not err.is_terminal) as bar:
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


def search(
    system: Annotated[str, typer.Argument(help=f"Synthetic system: {', '.join(SYSTEMS)}.")] = "plates2d",
    budget: Annotated[Optional[int], typer.Option(help="Samples to evaluate (default: the system's reference budget).")] = None,
    method: Annotated[str, typer.Option(help=f"Search method: {', '.join(rapt.METHODS)}.")] = "s-ndv",
    batch_size: Annotated[int, typer.Option("--batch-size", help="Samples per batch.")] = 100,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    store: Annotated[Optional[Path], typer.Option(help="SQLite study store; an existing one is resumed.")] = None,
    d_eps: Annotated[Optional[float], typer.Option("--d-eps", help="Boundary width for the quality metrics.")] = None,
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
    methods = [method] + ([baseline] if baseline not in ("none", method) else [])
    for i, m in enumerate(methods):
        study, elapsed = run_search(m, sut, bounds, budget, method=m, batch_size=batch_size, seed=seed,
                                    store=store if i == 0 else None, output_types=types)
        q = quality_table(sut, study.X, d_eps, seed=seed)
        rows.append((m, q, elapsed, study))

    table = Table(title=f"{system}: {budget} samples, D_eps = {d_eps:g}, seed {seed}")
    for col in ("method", "precision", "coverage", "mean distance", "time (s)", "precision ×", "coverage ×"):
        table.add_column(col, justify="right" if col != "method" else "left")
    base = rows[-1][1] if len(rows) > 1 else None
    for m, q, elapsed, _ in rows:
        ratio_p = f"{q['precision'] / base['precision']:.2f}" if base and base["precision"] > 0 else "-"
        ratio_c = f"{q['coverage'] / base['coverage']:.2f}" if base and base["coverage"] > 0 else "-"
        table.add_row(m, f"{q['precision']:.1%}", f"{q['coverage']:.1%}", f"{q['mean_distance']:.4f}",
                      f"{elapsed:.2f}", ratio_p, ratio_c)
    out.print(table)
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
    store: Annotated[Optional[Path], typer.Option(help="SQLite study store; an existing one is resumed.")] = None,
    stochastic: Annotated[bool, typer.Option(help="Navigation drift and current perturbations on.")] = False,
    baseline: Annotated[str, typer.Option(help="Method to compare against (or 'none').")] = "sobol",
) -> None:
    """Search a mission's scenarios for performance boundaries; print modes and boundary types."""
    import numpy as np

    import sim.uuv
    from sim.uuv.scoring import MODE_NAMES

    if baseline != "none" and baseline not in rapt.METHODS:
        fail(f"--baseline: unknown method {baseline!r}; choose one of: {', '.join(rapt.METHODS)}, none")
    mission = load_mission(mission_file)

    def run_root_scores(X):  # the search steers on mission and safety success (section 4.3.6)
        return sim.uuv.simulate(mission, X, seed=seed, stochastic=stochastic).scores[:, :2]

    results = []
    methods = [method] + ([baseline] if baseline not in ("none", method) else [])
    for i, m in enumerate(methods):
        found, elapsed = run_search(m, run_root_scores, mission.space, budget, method=m, batch_size=batch_size,
                                    seed=seed, store=store if i == 0 else None, output_types=("binary", "binary"))
        modes = (2 * found.Y[:, 0] + found.Y[:, 1]).astype(int)
        pairs = rapt.boundary_pairs(found.X, labels=modes) if np.unique(modes).size > 1 else None
        results.append((m, found, modes, pairs, elapsed))

    table = Table(title=f"{mission.name}: {budget} scenarios ({mission.dim}-D), seed {seed}")
    table.add_column("", justify="left")
    for m, *_ in results:
        table.add_column(m, justify="right")
    present = {m: sorted(set(modes.tolist())) for m, _, modes, _, _ in results}
    table.add_row("valid runs", *[f"{len(f.X):,}" for _, f, *_ in results])
    table.add_row("invalid scenarios", *[f"{len(f.X_failed):,}" for _, f, *_ in results])
    for k, name in enumerate(MODE_NAMES):
        table.add_row(f"mode {name}", *[f"{np.mean(modes == k):.1%}" for _, _, modes, _, _ in results])
    types = sorted({tuple(sorted((present[m][a], present[m][b]))) for m, _, _, bp, _ in results if bp
                    for a, b, _ in bp.types()})
    for a, b in types:
        cells = []
        for m, _, _, bp, _ in results:
            n = 0
            if bp is not None and a in present[m] and b in present[m]:
                n = len(bp.of_type(present[m].index(a), present[m].index(b)))
            total = len(bp) if bp is not None and len(bp) else 1
            cells.append(f"{n:,} ({n / total:.0%})")
        table.add_row(f"boundary {MODE_NAMES[a]}/{MODE_NAMES[b]}", *cells)
    table.add_row("median pair distance",
                  *[f"{np.median(bp.distance):.3f}" if bp is not None and len(bp) else "-" for *_, bp, _ in results])
    table.add_row("time (s)", *[f"{e:.1f}" for *_, e in results])
    out.print(table)
    if store is not None:
        out.print(f"study stored in {store} ({results[0][1].n_evaluated} scenarios)", soft_wrap=True, highlight=False)
