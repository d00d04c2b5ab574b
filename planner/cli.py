"""``rapt-plan``: the test engineer's command line.

``rapt-plan study MISSION`` searches a mission file's scenario space with the simulator
and reports the performance modes and boundary types it found, side by side with a
space-filling design (Figure 3.12).  ``rapt-plan search SYSTEM`` does the same on a
bundled synthetic system with known boundaries and prints how well it found them.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

import rapt
from planner.console import err, fail, out
from rapt.metrics import quality_table
from rapt.testfunctions import REFERENCE_SETTINGS, SYSTEMS, get_system, search_output_types

app = typer.Typer(no_args_is_help=True, add_completion=False, help=__doc__.splitlines()[0])


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


@app.callback()
def main() -> None:
    """Plan field tests of autonomous underwater vehicles from adaptive boundary searches."""


@app.command()
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


@app.command()
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
    mission = _load_mission(mission_file)

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


def _mission_and_scenario(mission_file: Path, scenario: str):
    import sim.uuv
    from planner.scenarios import resolve_scenario

    mission = _load_mission(mission_file)
    try:
        u, sid = resolve_scenario(mission, scenario)
        scen = sim.uuv.scenario.make_scenarios(mission, u[None, :])
    except ValueError as exc:
        fail(str(exc))
    if not scen.valid[0]:
        fail(f"--scenario: {scenario} is invalid for {mission.name} ({scen.invalid_reason[0]}); pick another")
    return mission, u, sid


def _wait_for_signal(until=None) -> None:
    """Block until SIGINT/SIGTERM (or ``until()`` is true), so a process stops cleanly."""
    import signal
    import threading

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    while not stop.wait(0.1):
        if until is not None and until():
            break


def _bus_session(connect: list[str], config_file: Optional[Path]):
    """A Zenoh session joining the bus: the config file as given, else the endpoints (loopback by default)."""
    from bridge.session import open_session

    try:
        return open_session(config_file=config_file) if config_file is not None else open_session(connect=connect)
    except (ValueError, OSError) as exc:
        fail(str(exc))


def _load_mission(mission_file: Path):
    """The mission file, loaded and validated, or a one-line error naming it."""
    import sim.uuv

    if not mission_file.is_file():
        fail(f"MISSION_FILE: {mission_file} does not exist; give the path of a mission TOML file")
    try:
        return sim.uuv.load_mission(mission_file)
    except ValueError as exc:
        fail(str(exc))


SurrogateOpt = Annotated[Optional[Path], typer.Option(
    "--surrogate", help="A trained surrogate (.npz from `rapt-plan surrogate`) flies instead of the expert "
                        "autonomy; it must have been trained for this mission.")]


def _load_surrogate(path: Optional[Path], mission):
    """The surrogate file for ``mission``, or a one-line error naming --surrogate."""
    if path is None:
        return None
    from sim.uuv.imitation.surrogate import Surrogate

    try:
        return Surrogate.load(path, mission)
    except (ValueError, OSError) as exc:
        fail(f"--surrogate: {exc}")


ScenarioOpt = Annotated[str, typer.Option("--scenario", help="Row number of the mission's Sobol design, or a "
                                                              "JSON file with 'u' or 'parameters'.")]
ZenohListen = Annotated[list[str], typer.Option("--zenoh-listen", help="Zenoh endpoints to listen on.")]
ZenohConnect = Annotated[list[str], typer.Option("--zenoh-connect", help="Zenoh endpoints to connect to.")]
ZenohConfig = Annotated[Optional[Path], typer.Option("--zenoh-config", help="Zenoh config file (real deployments).")]
Vehicle = Annotated[str, typer.Option("--vehicle", help="Vehicle name on the bus.")]


@app.command()
def run(
    mission_file: Annotated[Path, typer.Argument(metavar="MISSION_OR_PLAN",
                                                 help="Mission file (TOML), or a plan.json from rapt-plan generate.")],
    scenario: Annotated[str, typer.Option("--scenario", help="Row number of the mission's Sobol design, or a JSON "
                                                            "file with 'u' or 'parameters'; with a plan, a scenario "
                                                            "id such as pair1a.")] = "0",
    speedup: Annotated[Optional[float], typer.Option(help="Real time times this factor (default: lock-step).")] = None,
    log: Annotated[Optional[Path], typer.Option(help="Record the bus to this MCAP file.")] = None,
    timeout: Annotated[float, typer.Option(help="Give up after this many wall seconds.")] = 600.0,
    inject_bias: Annotated[Optional[str], typer.Option(
        "--inject-bias", help="Fly a biased vehicle for rehearsal, e.g. speed=1.15,current_offset=0.3 "
                              "(speed, current_scale, current_offset, heading, battery, start_time; see sim.uuv.bias). "
                              "Not written to the log.")] = None,
    stochastic: Annotated[bool, typer.Option(help="Navigation drift and current perturbations on (seeded).")] = False,
    seed: Annotated[int, typer.Option(help="Seed of the stochastic effects.")] = 0,
    surrogate: SurrogateOpt = None,
) -> None:
    """Fly one scenario software-in-the-loop: front-seat, bridge, autonomy (and logger).

    With --surrogate the learned policy commands the vehicle while the expert autonomy
    keeps running beside it; the expert's commands are on the bus and in the log.
    """
    import numpy as np

    import sim.uuv
    from planner.sil import run_sil
    from sim.uuv.bias import parse_bias

    try:
        bias = parse_bias(inject_bias) if inject_bias is not None else None
    except ValueError as exc:
        fail(f"--inject-bias: {exc}")
    pid = ""
    if mission_file.suffix == ".json" or mission_file.is_dir():
        from planner.plans import load_plan

        try:
            plan = load_plan(mission_file)
            mission, u, sid, pid = plan.mission, plan.u(scenario), scenario, plan.id
        except ValueError as exc:
            fail(str(exc))
        source = str(plan.mission_file)
    else:
        mission, u, sid = _mission_and_scenario(mission_file, scenario)
        source = str(mission_file)
    if speedup is not None and speedup <= 0:
        fail(f"--speedup: expected a factor > 0, got {speedup}")
    learned = _load_surrogate(surrogate, mission)
    try:
        result = run_sil(mission, u, log_path=log, speedup=speedup, timeout_s=timeout, scenario_id=sid,
                         mission_file=source, plan_id=pid, bias=bias, stochastic=stochastic, seed=seed,
                         surrogate=learned)
    except (ValueError, RuntimeError, TimeoutError) as exc:
        fail(str(exc))
    batch = sim.uuv.simulate(mission, u[None, :], bias=bias, seed=seed, stochastic=stochastic, surrogate=learned)
    same = bool(np.array_equal(result.scores, batch.scores[0]))
    names = batch.names
    mode = ("TF", "SS", "MS", "TS")[int(2 * result.scores[0] + result.scores[1])]
    table = Table(title=f"{mission.name} scenario {sid}: software in the loop")
    table.add_column("", justify="left")
    table.add_column("value", justify="right")
    table.add_row("ended", result.ended)
    if learned is not None:
        table.add_row("flown by", f"surrogate {surrogate.name} (expert commands recorded)")
    table.add_row("mode", mode)
    if bias is not None:
        table.add_row("injected bias", str(bias))
    table.add_row("simulated time", f"{result.sim_s:,.0f} s in {result.wall_s:.1f} s ({result.speedup:,.0f}x)")
    for name in ("mission_areas", "transmission", "recovery", "nogo_areas", "mission.battery_left"):
        if name in names:
            table.add_row(name, f"{result.scores[names.index(name)]:g}")
    if stochastic:  # the log holds what the navigation believed, the batch scores ground truth
        table.add_row("batch simulator's mode (ground truth)", ("TF", "SS", "MS", "TS")[int(batch.modes[0])])
    else:
        table.add_row("same scores as the batch simulator" + (" (same bias)" if bias is not None else ""),
                      "yes" if same else "NO")
    if log is not None:
        table.add_row("log", str(log))
    out.print(table)


@app.command()
def generate(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Directory for plan.json and the per-scenario files.")],
    budget: Annotated[int, typer.Option(help="Runs in the search.")] = 3000,
    pairs: Annotated[int, typer.Option(help="Boundary pairs in the plan.")] = 5,
    global_fraction: Annotated[float, typer.Option(help="Share of the budget for the space-filling start.")] = 0.2,
    dithers: Annotated[int, typer.Option(help="Stochastic dither runs per pair.")] = 2000,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    batch_size: Annotated[Optional[int], typer.Option("--batch-size", help="Runs per search batch "
                                                        "(default: about 40 batches of 250 to 5,000).")] = None,
    resume: Annotated[bool, typer.Option(help="Continue the study stored in OUT/study.db (or start it: "
                                              "nothing evaluated is run again).")] = False,
    executor: Annotated[str, typer.Option(help="local, processes or dask://host:port.")] = "local",
    refine: Annotated[bool, typer.Option("--refine", help="Sharpen each pair with a focused second search "
                                                         "on its own sub-scores.")] = False,
    refine_runs: Annotated[int, typer.Option("--refine-runs", help="Runs per pair of --refine.")] = 12,
    surrogate: Annotated[Optional[Path], typer.Option(
        "--surrogate", help="Search with a learned surrogate of the autonomy (section 6.2.3): load this .npz "
                            "(trained for this mission), or train one (75 annotated + 25 held-out expert runs) "
                            "and save it here; the expert then confirms the candidate pairs.")] = None,
    confirm_runs: Annotated[int, typer.Option("--confirm-runs", help="Expert runs that check the surrogate's "
                                                                     "candidate pairs (two per pair).")] = 100,
) -> None:
    """Search a mission, choose boundary pairs, dither them and write a field plan."""
    from planner.generate import GenerateConfig, generate as run_generate, make_executor

    mission = _load_mission(mission_file)
    store = out_dir / ("study.db" if surrogate is None else "study-surrogate.db")
    if store.exists() and not resume:
        fail(f"--out: {store} already holds a study; add --resume to continue it or choose another directory")
    cfg = GenerateConfig(budget=budget, pairs=pairs, global_fraction=global_fraction, seed=seed,
                         batch_size=batch_size, dithers=dithers, store=store, refine=refine_runs if refine else 0,
                         confirm_runs=confirm_runs, surrogate_file=str(surrogate or ""))
    try:
        cfg.check()
    except ValueError as exc:
        fail(str(exc))
    if surrogate is not None:
        from planner.surrogate import load_or_train

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
    with Progress(TextColumn("{task.description:>8}"), BarColumn(), MofNCompleteColumn(),
                  TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), console=err, transient=True,
                  disable=not err.is_terminal) as bar:
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
    table = Table(title=f"{mission.name}: field plan in {out_dir}")
    for col in ("pair", "sub-boundary", "modes", "distance", "P(predicted mode) a / b"):
        table.add_column(col, justify="left" if col == "sub-boundary" else "right")
    by_id = {sc["id"]: sc for sc in plan["scenarios"]}
    for p in plan["pairs"]:
        probs = [by_id[s]["dithering"].get("p_predicted_mode") for s in p["scenarios"]]
        table.add_row(str(p["id"]), ", ".join(p["elements"]), " / ".join(p["modes"]), f"{p['distance']:.3f}",
                      " / ".join("-" if v is None else f"{v:.0%}" for v in probs))
    out.print(table)
    out.print(f"{plan['study']['valid_runs']:,} valid runs; plan.json and {len(plan['scenarios'])} scenarios "
              f"(.plan, .waypoints, .geojson) written", soft_wrap=True, highlight=False)
    if surrogate is not None:
        s = plan["study"]["surrogate"]
        out.print(f"surrogate search: {s['confirmed']} of {s['candidates']} candidate pairs confirmed by the expert; "
                  f"expert runs: {s['expert_runs']['training']} training + {s['expert_runs']['confirmation']} "
                  "confirmation", soft_wrap=True, highlight=False)


@app.command("surrogate")
def surrogate_cmd(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    out_file: Annotated[Path, typer.Option("--out", help="Surrogate file to write (.npz).")],
    method: Annotated[str, typer.Option(help="qdagger, dagger or supervised (behavioural cloning).")] = "qdagger",
    quantile: Annotated[float, typer.Option(help="Q-DAgger: aggregate the states predicted worse than this "
                                                 "quantile of each new set (0.5, 0.75).")] = 0.5,
    runs: Annotated[int, typer.Option(help="Annotated expert runs in all.")] = 75,
    runs_per_iteration: Annotated[int, typer.Option("--runs-per-iteration", help="New runs per update.")] = 5,
    epochs: Annotated[int, typer.Option(help="Training epochs per update (warm-started).")] = 30,
    mixing: Annotated[float, typer.Option(help="Update i's runs obey the expert on a share mixing**i of their steps "
                                               "(DAgger's beta; 0: the learner flies every step).")] = 0.5,
    select_runs: Annotated[int, typer.Option("--select-runs", help="Held-out expert runs that choose which update's "
                                                                 "policy to keep (best mode accuracy; 0: the last) "
                                                                 "and its goal threshold.")]
        = 25,
    validate: Annotated[int, typer.Option(help="Sobol scenarios to measure mode accuracy on after each update "
                                               "(0: none).")] = 256,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
) -> None:
    """Train a surrogate of a mission's back-seat autonomy by imitation learning (chapter 6)."""
    from scipy.stats import qmc

    import sim.uuv
    from planner.surrogate import mode_agreement, train_surrogate

    mission = _load_mission(mission_file)
    if out_file.suffix != ".npz":
        fail(f"--out: a surrogate file ends in .npz, got {out_file}")
    if validate < 0:
        fail(f"--validate: expected a number of scenarios >= 0, got {validate}")
    Xv = qmc.Sobol(mission.dim, seed=seed).random(validate) if validate else None
    expert = sim.uuv.simulate(mission, Xv) if validate else None
    table = Table(title=f"{mission.name}: {method} imitation of the autonomy")
    for col in ("iteration", "expert runs", "samples", "fit (s)", "train MSE") + (("mode accuracy",) if validate else ()):
        table.add_column(col, justify="right")

    def on_iteration(rec, policy):
        row = [str(rec.iteration), str(rec.runs), f"{rec.samples:,}", f"{rec.fit_s:.1f}", f"{rec.loss:.4f}"]
        if validate:
            from sim.uuv.imitation.surrogate import Surrogate

            row.append(f"{mode_agreement(mission, Surrogate.for_mission(mission, policy), Xv, expert):.1%}")
        table.add_row(*row)
        err.print(" ".join(row), highlight=False)

    try:
        sur = train_surrogate(mission, method=method, quantile=quantile, runs=runs,
                              runs_per_iteration=runs_per_iteration, epochs=epochs, mixing=mixing,
                              select_runs=select_runs, seed=seed, on_iteration=on_iteration)
    except ValueError as exc:
        fail(f"--{str(exc)}" if str(exc).split(":")[0] in ("method", "quantile", "epochs") else str(exc))
    sur.save(out_file)
    out.print(table)
    t = sur.training
    kept = (f"update {t['chosen_iteration']} kept ({t['selection_accuracy']:.1%} on {t['select_runs']} held-out runs), "
            f"goal threshold {sur.goal_threshold:+.1f}" if t["select_runs"] else "last update kept")
    out.print(f"surrogate of {mission.name} written to {out_file} ({t['runs']} expert runs: {t['annotated_runs']} "
              f"annotated + {t['select_runs']} held out; {kept}; {sur.spec.size} features)",
              soft_wrap=True, highlight=False)


@app.command()
def compare(
    plan_dir: Annotated[Path, typer.Argument(help="Plan directory (or its plan.json) from rapt-plan generate.")],
    logs: Annotated[list[Path], typer.Argument(help="MCAP logs of the plan's runs (SIL or the real vehicle).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Directory for comparison.json and comparison.html.")]
        = Path("comparison"),
    dithers: Annotated[int, typer.Option(help="Stochastic runs checking each adjusted scenario (0: none).")] = 20,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    fit: Annotated[Optional[str], typer.Option(help="Bias parameters to fit, comma-separated (default: all of "
                                                    "speed, current_scale, current_offset, heading, battery, "
                                                    "start_time).")] = None,
) -> None:
    """Compare run logs with the plan: predicted vs observed, execution bias, re-plan."""
    from planner.compare import CompareConfig, compare as run_compare
    from sim.uuv.bias import BIAS_NAMES

    names = BIAS_NAMES
    if fit is not None:
        names = tuple(n.strip() for n in fit.split(",") if n.strip())
        bad = [n for n in names if n not in BIAS_NAMES]
        if bad or not names:
            fail(f"--fit: unknown bias parameter {bad[0] if bad else fit!r}; choose from {', '.join(BIAS_NAMES)}")
    if dithers < 0:
        fail(f"--dithers: expected a number of runs >= 0, got {dithers}")
    for p in logs:
        if not p.is_file():
            fail(f"LOGS: {p} does not exist; give the .mcap files of the plan's runs")
    with err.status("comparing", spinner="dots") if err.is_terminal else _nullcontext() as status:
        def progress(stage: str) -> None:
            if status is not None:
                status.update(stage)

        try:
            result = run_compare(plan_dir, logs, out_dir, CompareConfig(dithers=dithers, seed=seed, fit=names),
                                 progress)
        except ValueError as exc:
            fail(str(exc))
    for lg in result["logs"]:
        for problem in lg["lost"]:
            err.print(f"[yellow]warning:[/] {Path(lg['path']).name}: {problem}", highlight=False, soft_wrap=True)
    table = Table(title=f"{result['plan']['mission']}: {len(result['scenarios'])} run(s) against plan "
                        f"{result['plan']['id']}")
    for col in ("scenario", "predicted", "observed", "corrected", "path error (m)", "corrected (m)"):
        table.add_column(col, justify="left" if col == "scenario" else "right")
    for r in result["scenarios"]:
        pe, pc = r["path_error_m"], r["path_error_corrected_m"]
        table.add_row(r["id"], r["predicted_mode"], r["observed_mode"] or "end not logged", r["corrected_mode"],
                      "-" if pe is None else f"{pe:.1f}", "-" if pc is None else f"{pc:.1f}")
    out.print(table)
    bias = Table(title="execution bias (fitted jointly to all logs)")
    for col in ("parameter", "estimate", "std. error", "unit"):
        bias.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    units = result["bias_fit"]["units"]
    for n, v in result["bias"].items():
        se = "not identifiable" if v["stderr"] is None else f"{v['stderr']:.2g}"
        bias.add_row(n, f"{v['estimate']:.4g}", se, units[n])
    out.print(bias)
    ag = result["mode_agreement"]
    pct = (lambda v: "-" if v is None else f"{v:.0%}")
    out.print(f"mode agreement: {pct(ag['uncorrected'])} as planned, {pct(ag['corrected'])} with the fitted bias "
              f"({ag['scenarios']} scenarios with a logged end)", highlight=False, soft_wrap=True)
    flagged = [p for p in result["pairs"] if p["flagged"]]
    for p in flagged:
        out.print(f"pair {p['id']} ({' / '.join(p['scenarios'])}) flagged: {p['reason']}", highlight=False,
                  soft_wrap=True)
    for q in result["proposals"]:
        if q["found"]:
            mv = q["moved"]
            out.print(f"  propose {q['id']}: {mv['parameter']} {mv['from']:.6g} -> {mv['to']:.6g} "
                      f"(under the bias: {q['predicted_mode_under_bias']})" if isinstance(mv["from"], float) else
                      f"  propose {q['id']}: {mv['parameter']} {mv['from']} -> {mv['to']}", highlight=False,
                      soft_wrap=True)
        else:
            out.print(f"  {q['variant_of']}: {q['note']}", highlight=False, soft_wrap=True)
    out.print(f"comparison.json and comparison.html written to {out_dir}", highlight=False, soft_wrap=True)


class _nullcontext:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


@app.command()
def frontseat(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    mavlink: Annotated[str, typer.Option(help="pymavlink connection to serve on, e.g. udpin:127.0.0.1:14550.")],
    scenario: ScenarioOpt = "0",
    speedup: Annotated[Optional[float], typer.Option(help="Real time times this factor (default: lock-step).")] = None,
) -> None:
    """Serve the simulated front-seat of one scenario on a MAVLink connection."""
    from sim.uuv.frontseat import FrontSeat

    mission, u, _ = _mission_and_scenario(mission_file, scenario)
    try:
        fs = FrontSeat(mission, u, mavlink, lockstep=speedup is None, speedup=speedup or 1.0)
    except (ValueError, OSError) as exc:
        fail(f"--mavlink: {exc}")
    import threading

    thread = threading.Thread(target=fs.serve, daemon=True)
    thread.start()
    _wait_for_signal()
    fs.stop()
    thread.join(timeout=5)
    fs.close()


@app.command("bridge")
def bridge_cmd(
    mavlink: Annotated[str, typer.Option(help="The vehicle's MAVLink connection (pymavlink string).")],
    vehicle: Vehicle = "uuv1",
    zenoh_listen: ZenohListen = ["tcp/127.0.0.1:7447"],
    zenoh_connect: ZenohConnect = [],
    zenoh_config: ZenohConfig = None,
    allow_commands: Annotated[bool, typer.Option("--allow-commands", help="Forward back-seat set-points.")] = False,
    signing_key: Annotated[Optional[Path], typer.Option(help="MAVLink 2 signing key file (32 bytes).")] = None,
    geofence: Annotated[Optional[str], typer.Option(help="north_min,north_max,east_min,east_max in m.")] = None,
    max_rate: Annotated[Optional[float], typer.Option("--max-rate", help="Set-points per second at most.")] = None,
    arm: Annotated[bool, typer.Option("--arm", help="Once the vehicle is heard: GUIDED and arm "
                                                     "(needs --allow-commands).")] = False,
) -> None:
    """Join a vehicle's MAVLink port (simulated or real) to the Zenoh bus."""
    import time
    from bridge.mavlink_bridge import MavlinkBridge
    from bridge.session import zenoh_config as make_config

    fence = None
    if geofence is not None:
        try:
            fence = [float(v) for v in geofence.split(",")]
        except ValueError:
            fail(f"--geofence: expected four numbers north_min,north_max,east_min,east_max, got {geofence!r}")
    try:
        conf = (make_config(config_file=zenoh_config) if zenoh_config is not None
                else make_config(listen=zenoh_listen, connect=zenoh_connect))
        if arm and not allow_commands:
            fail("--arm: arming sends commands to the vehicle; add --allow-commands")
        with MavlinkBridge(mavlink, conf, vehicle=vehicle, allow_commands=allow_commands, geofence=fence,
                           max_rate_hz=max_rate, signing_key=signing_key) as link:
            if arm:
                deadline = time.monotonic() + 30
                while link.target is None and time.monotonic() < deadline:
                    time.sleep(0.05)
                if link.target is None:
                    fail("--mavlink: no vehicle HEARTBEAT within 30 s; check the connection string")
                link.set_mode("GUIDED")
                link.arm(True)
            _wait_for_signal()
    except (ValueError, OSError) as exc:
        fail(str(exc))


@app.command()
def autonomy(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    scenario: ScenarioOpt = "0",
    vehicle: Vehicle = "uuv1",
    source: Annotated[str, typer.Option(help="Name this autonomy publishes its set-points under.")] = "autonomy",
    zenoh_connect: ZenohConnect = ["tcp/127.0.0.1:7447"],
    zenoh_config: ZenohConfig = None,
    surrogate: SurrogateOpt = None,
) -> None:
    """Run the back-seat autonomy of one scenario on the bus (or a trained surrogate of it)."""
    from planner.backseat import BackSeat

    mission, u, _ = _mission_and_scenario(mission_file, scenario)
    learned = _load_surrogate(surrogate, mission)
    session = _bus_session(zenoh_connect, zenoh_config)
    try:
        with BackSeat(session, vehicle, mission, u, source=source, surrogate=learned):
            _wait_for_signal()
    finally:
        session.close()


@app.command("log")
def log_cmd(
    out_file: Annotated[Path, typer.Option("--out", help="MCAP file to write.")],
    vehicle: Vehicle = "uuv1",
    zenoh_connect: ZenohConnect = ["tcp/127.0.0.1:7447"],
    zenoh_config: ZenohConfig = None,
) -> None:
    """Record a vehicle's bus traffic to MCAP until stopped."""
    from bridge.logger import McapLogger

    session = _bus_session(zenoh_connect, zenoh_config)
    try:
        with McapLogger(out_file, session, vehicle=vehicle):
            _wait_for_signal()
    finally:
        session.close()


# Chapter 5's second system under test: self-righting ground robots (planner/selfright/).
console = out  # the command's --out option is called out


@app.command("selfright")
def selfright_command(
    robot_file: Annotated[Path, typer.Argument(metavar="ROBOT_FILE", help="Robot file, TOML or URDF (by suffix: .toml, "
                                               ".urdf), e.g. examples/robots/1dof.toml.")],
    out: Annotated[Path, typer.Option("--out", help="Directory for graph.json, graph.graphml, states.png, report.md.")],
    slope: Annotated[Optional[float], typer.Option(help="Ground slope in degrees (default: the robot file's, else 0).")] = None,
    budget: Annotated[int, typer.Option(help="Queries to the stability function (a planar robot's last hull may add a few faces).")] = 1000,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    batch_size: Annotated[int, typer.Option("--batch-size", help="Queries per batch.")] = 50,
    r_min: Annotated[float, typer.Option("--r-min", help="Boundary resolution, degrees (search ends below it).")] = 1.0,
    r_max: Annotated[float, typer.Option("--r-max", help="Interior resolution, degrees.")] = 10.0,
    refine: Annotated[float, typer.Option("--refine", help="Share of the budget kept to bisect each transition's "
                                          "boundary pair below --r-min (0: off).")] = 0.1,
    outcomes: Annotated[bool, typer.Option("--outcomes", help="Also steer the search by where states tip to "
                                           "(finds stable islands narrower than a coarse --r-max such as 45; costs at a fine one).")] = False,
    max_edge: Annotated[Optional[float], typer.Option("--max-edge", help="Gabriel graph's longest edge, degrees "
                                                      "(default: 2 to 4 x --r-max, by sample density).")] = None,
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
    study = adaptive_study(robot, slope, budget, seed=seed, batch_size=batch_size, r_min_deg=r_min, r_max_deg=r_max,
                           refine=refine, outcomes=outcomes)
    result = analyse(study, max_edge=None if max_edge is None else np.radians(max_edge))
    doc = write_outputs(study, result, out)
    energy = doc["mean_energy_to_home_J"]
    console.print(f"{robot.name} on a {slope:g}° slope: {study.queries:,} queries"
              f"{' (resolution reached)' if study.extra.get('stopped_by_resolution') else ''}, "
              f"{len(doc['nodes'])} nodes, {len(doc['edges'])} transitions; "
              f"self-rightable {doc['self_rightable_fraction']:.1%}, mean energy to home "
              f"{'n/a' if energy is None else f'{energy:.2f} J'}; wrote {out}/graph.json, graph.graphml, states.png, report.md",
              soft_wrap=True, highlight=False)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
