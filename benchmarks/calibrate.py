"""Calibrating the vehicle model from logs of a vehicle that is not the planner's (issue 23, part C), measured.

A plan of ``examples/range2017.toml`` (4 pairs: 8 scenarios) is flown on the bare-autopilot
front-seat (``rapt-plan frontseat ... --bare --speedup S``, vehicle-paced ``rapt-plan run
PLAN --scenario ID --mavlink ...``) running a copy of the mission whose ``[vehicle]`` is
another vehicle's: slower (``speed_gain`` 0.8), slower to turn (8 deg/s, yaw time constant
5 s) and hungrier (hotel 60 W, drag 220 W).  The planner's mission is the unchanged file.

The logs are split in two halves (scenarios 1, 3, 5, 7 and 2, 4, 6, 8 of the plan).
``rapt-plan calibrate`` runs on one half; the other half is predicted with the batch
simulator, the plan's autonomy flying either the mission's vehicle (before) or the
calibrated one (after: ``sim.uuv.simulate(..., plant=calibrated vehicle)``), and set
against what was logged: mode agreement (observed mode = the logged track scored by the
mission's scorer) and RMS path error (distance at the same scenario times).  Then the
halves swap.  Fitted versus true values are printed too.

Run:  python benchmarks/calibrate.py [--speedup 10] [--jobs 2] [--work DIR] [--quick]

``--quick``: a 2-pair plan (4 scenarios) at speed-up 25, each flight cut after 30 s wall
(about 750 vehicle seconds); the fit and its residuals only, no modes.

``--work`` keeps the plan and logs; run again with it, only what is missing there is flown.  At
speed-up 10 each scenario takes up to 4.5 minutes of wall time; two fly side by side.  A
run the watchdog ended (the rig fell behind the vehicle's clock: a one-second stall of a
loaded machine is ten vehicle seconds without a set-point) is flown once more, and
otherwise counts as no observation.  Higher speed-ups work on an idle machine.
:func:`rows` returns the result (rows per fold, fitted values) for ``benchmarks/compare.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
MISSION = ROOT / "examples" / "range2017.toml"
#: The vehicle flown: another vehicle's [vehicle] values (the rest of the file's block is kept).
TRUE_VEHICLE = {
    "speed_gain": 0.8,
    "max_turn_rate_dps": 8.0,
    "yaw_time_constant_s": 5.0,
    "hotel_w": 60.0,
    "drag_w": 220.0,
}
#: --quick: wall seconds each flight is cut at (calibration needs segments, not ends).
QUICK_CUT_S = 30.0


def _rapt_plan() -> list[str]:
    exe = Path(sys.executable).with_name("rapt-plan")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]


def other_vehicle_mission(path: Path) -> Path:
    """A copy of the mission file whose [vehicle] block is :data:`TRUE_VEHICLE` (same mission name)."""
    lines = MISSION.read_text().splitlines()
    start = lines.index("[vehicle]")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    keep = [ln for ln in lines[start + 1 : end] if ln.split("=")[0].strip() not in TRUE_VEHICLE]
    block = ["[vehicle]", *[f"{k} = {v!r}" for k, v in TRUE_VEHICLE.items()], *keep]
    path.write_text("\n".join(lines[:start] + block + lines[end:]) + "\n")
    return path


def make_plan(work: Path, seed: int = 0, pairs: int = 4) -> Path:
    """A small plan of the mission (budget 1000, ``pairs`` pairs, no dithers) in ``work/plan``."""
    import sim.uuv
    from planner.plan.generate import GenerateConfig, generate

    plan_dir = work / "plan"
    if not (plan_dir / "plan.json").is_file():
        generate(
            sim.uuv.load_mission(MISSION),
            MISSION,
            plan_dir,
            GenerateConfig(budget=1000, batch_size=250, dithers=0, pairs=pairs, seed=seed),
        )
    return plan_dir / "plan.json"


def fly(
    plan_json: Path, vehicle_toml: Path, sid: str, u: np.ndarray, log: Path, speedup: float, cut_s: float | None = None
) -> str:
    """One scenario on the bare front-seat running ``vehicle_toml`` (stopped after ``cut_s`` wall seconds
    when given); returns "" or what went wrong."""
    from planner.fly.run_bus import free_port

    port = free_port()
    scen = log.with_suffix(".scenario.json")
    scen.write_text(json.dumps({"u": [float(v) for v in u]}))
    env = {**os.environ, "COLUMNS": "200"}
    vehicle = subprocess.Popen(
        _rapt_plan()
        + ["frontseat", str(vehicle_toml), "--mavlink", f"udpin:127.0.0.1:{port}", "--bare"]
        + ["--speedup", f"{speedup:g}", "--scenario", str(scen)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
    )
    try:
        limit = cut_s if cut_s is not None else 2700 / speedup * 1.5 + 120
        tmp = log.with_suffix(".partial.mcap")
        run = subprocess.run(
            _rapt_plan()
            + ["run", str(plan_json), "--scenario", sid, "--mavlink", f"udpout:127.0.0.1:{port}", "--no-guard"]
            + ["--log", str(tmp), "--timeout", f"{limit:.0f}"],
            capture_output=True,
            text=True,
            timeout=limit + 120,
            cwd=ROOT,
            env=env,
        )
        if run.returncode != 0:
            return f"rapt-plan run exit {run.returncode}: {(run.stderr or run.stdout).strip()[-300:]}"
        os.replace(tmp, log)
        return ""
    finally:
        vehicle.terminate()
        try:
            vehicle.wait(timeout=20)
        except subprocess.TimeoutExpired:
            vehicle.kill()
            vehicle.wait()


def observed_mode(mission, u, run) -> str | None:
    """The logged run's mode (the track scored by the mission's scorer); None when its end is not
    in the log or the watchdog ended it (a rig that fell behind, not the vehicle: no observation)."""
    from sim.uuv.replay import score_track
    from sim.uuv.scoring import mode_name

    if not run.steps.shape[0] or not run.has_end or run.ended.startswith("watchdog"):
        return None
    return mode_name(score_track(mission, u, run.track, run.wp_aborted, run.return_reason))


def fly_checked(
    plan_json: Path, vehicle_toml: Path, sid: str, u: np.ndarray, log: Path, speedup: float, cut_s: float | None = None
) -> str:
    """:func:`fly`, once more when the watchdog ended the run (the rig fell behind the vehicle's clock)."""
    from planner.review.logs import read_run

    error = ""
    for _ in range(2):
        error = fly(plan_json, vehicle_toml, sid, u, log, speedup, cut_s)
        if error or not read_run(log).ended.startswith("watchdog"):
            return error
        error = f"ended by the watchdog ({read_run(log).ended})"
    return error


def path_rms(track: np.ndarray, pred: np.ndarray | None) -> float:
    """RMS distance (m) between the logged and the predicted track at the same times (over the span both cover)."""
    if pred is None or not track.shape[0]:
        return float("nan")
    n = min(track.shape[0], pred.shape[0])
    return float(np.sqrt(np.mean((track[:n, 1] - pred[:n, 1]) ** 2 + (track[:n, 2] - pred[:n, 2]) ** 2)))


def evaluate(plan_json: Path, logs: dict[str, Path], work: Path, seed: int = 0, modes: bool = True) -> dict:
    """Calibrate on each half, predict the other; returns the rows and the fitted values per fold."""
    import sim.uuv
    from planner.common.plans import load_plan
    from planner.review.calibrate import calibrate
    from planner.review.logs import read_run
    from planner.review.vehicle_fit import FITTED
    from sim.uuv.scoring import MODE_NAMES

    plan = load_plan(plan_json)
    m = plan.mission
    ids = sorted(logs)
    halves = (ids[0::2], ids[1::2])
    runs = {sid: read_run(logs[sid]) for sid in ids}
    folds = []
    for k, (fit_ids, test_ids) in enumerate((halves, halves[::-1])):
        out = work / f"calibrated_{k + 1}.toml"
        started = time.perf_counter()
        cal = calibrate(MISSION, [logs[s] for s in fit_ids], out, seed=seed)
        fit_s = time.perf_counter() - started
        U = np.array([plan.u(s) for s in test_ids])
        before = sim.uuv.simulate(m, U, trajectories=True)
        after = sim.uuv.simulate(m, U, trajectories=True, plant=cal.vehicle)
        rows = []
        for i, sid in enumerate(test_ids):
            run = runs[sid]
            rows.append(
                {
                    "scenario": sid,
                    "observed": observed_mode(m, plan.u(sid), run) if modes else None,
                    "before": MODE_NAMES[before.modes[i]],
                    "after": MODE_NAMES[after.modes[i]],
                    "path_before_m": path_rms(run.track, before.trajectory(i)),
                    "path_after_m": path_rms(run.track, after.trajectory(i)),
                }
            )
        fitted = {
            n: (float(getattr(cal.vehicle, n)), float(cal.stderr[n]), bool(cal.estimate.identified[n])) for n in FITTED
        }
        folds.append(
            {
                "fit_on": fit_ids,
                "test_on": test_ids,
                "rows": rows,
                "fitted": fitted,
                "rms_before": cal.rms_before,
                "rms_after": cal.rms_after,
                "fit_s": fit_s,
            }
        )
    return {"folds": folds, "file": dataclasses.asdict(m.vehicle)}


def rows(speedup: float = 10.0, jobs: int = 2, work: Path | None = None, seed: int = 0, quick: bool = False) -> dict:
    """Fly (what is missing in ``work``), calibrate and predict: :func:`evaluate`'s result plus flight notes."""
    import sim.uuv  # noqa: F401  (imported before the pool, once)
    from planner.common.plans import load_plan

    work = Path(work) if work is not None else Path(tempfile.mkdtemp(prefix="rapt_calibrate_"))
    work.mkdir(parents=True, exist_ok=True)
    plan_json = make_plan(work, seed, pairs=2 if quick else 4)
    vehicle_toml = other_vehicle_mission(work / "other_vehicle.toml")
    plan = load_plan(plan_json)
    ids = [s["id"] for s in plan.scenarios]
    logs_dir = work / "logs"
    logs_dir.mkdir(exist_ok=True)
    todo = [sid for sid in ids if not (logs_dir / f"{sid}.mcap").is_file()]
    cut = QUICK_CUT_S if quick else None
    started = time.perf_counter()
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        errors = dict(
            zip(
                todo,
                pool.map(
                    lambda sid: fly_checked(
                        plan_json, vehicle_toml, sid, plan.u(sid), logs_dir / f"{sid}.mcap", speedup, cut
                    ),
                    todo,
                ),
            )
        )
    flown_s = time.perf_counter() - started
    logs = {sid: logs_dir / f"{sid}.mcap" for sid in ids if (logs_dir / f"{sid}.mcap").is_file()}
    result = evaluate(plan_json, logs, work, seed, modes=not quick)
    result.update({"work": str(work), "flight_errors": {k: v for k, v in errors.items() if v}, "flown_s": flown_s})
    return result


def _pct(hits: int, n: int) -> str:
    return f"{hits}/{n}" if n else "-"


def report(result: dict) -> str:
    """The markdown tables of :func:`rows`' result."""
    out = []
    out.append(
        "| fold | fitted on | scenario | observed | predicted before | after | path RMS before (m) | after (m) |"
    )
    out.append("|---|---|---|---|---|---|---|---|")
    total = {"before": 0, "after": 0, "n": 0, "pb": [], "pa": []}
    for k, f in enumerate(result["folds"]):
        for r in f["rows"]:
            out.append(
                f"| {k + 1} | {', '.join(f['fit_on'])} | {r['scenario']} | {r['observed'] or 'no observation'} | "
                f"{r['before']} | {r['after']} | {r['path_before_m']:.1f} | {r['path_after_m']:.1f} |"
            )
            if r["observed"] is not None:
                total["n"] += 1
                total["before"] += r["before"] == r["observed"]
                total["after"] += r["after"] == r["observed"]
            total["pb"].append(r["path_before_m"])
            total["pa"].append(r["path_after_m"])
    n = total["n"]
    out.append("")
    out.append(
        f"Mode agreement on the held-out halves: {_pct(total['before'], n)} before calibration, "
        f"{_pct(total['after'], n)} after; mean path RMS {np.nanmean(total['pb']):.1f} m before, "
        f"{np.nanmean(total['pa']):.1f} m after."
    )
    out.append("")
    return "\n".join(out)


def fitted_table(result: dict) -> str:
    """Fitted versus true [vehicle] values per fold (true: the flown vehicle; file: the planner's)."""
    from planner.review.vehicle_fit import FITTED

    file = result["file"]
    head = "| field | file (planner) | true (flown) | " + " | ".join(
        f"fold {k + 1} fit ± s.e." for k in range(len(result["folds"]))
    )
    out = [head + " |", "|---|---|---|" + "---|" * len(result["folds"])]
    for n in FITTED:
        true = TRUE_VEHICLE.get(n, file[n])
        cells = []
        for f in result["folds"]:
            v, se, ident = f["fitted"][n]
            cells.append(f"{v:.4g} ± {se:.2g}" if ident else f"{v:.4g} (not identified)")
        out.append(f"| {n} | {file[n]:.4g} | {true:.4g} | " + " | ".join(cells) + " |")
    out.append("")
    for k, f in enumerate(result["folds"]):
        b, a = f["rms_before"], f["rms_after"]
        out.append(
            f"Fold {k + 1} segment residual RMS (file -> calibrated): position {b['position_m']:.2f} -> "
            f"{a['position_m']:.2f} m, heading {b['heading_deg']:.2f} -> {a['heading_deg']:.2f} deg, energy "
            f"{b['energy_wh']:.3f} -> {a['energy_wh']:.3f} Wh; fit {f['fit_s']:.0f} s."
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speedup", type=float, default=10.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--work", type=Path, default=None, help="Directory for the plan, logs and calibrated files.")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--quick", action="store_true", help="4 scenarios, each cut after 30 s wall: the fit only, no modes (~2 min)"
    )
    args = ap.parse_args(argv)
    if args.quick and args.speedup == 10.0:
        args.speedup = 25.0
    result = rows(args.speedup, args.jobs, args.work, args.seed, quick=args.quick)
    if result["flight_errors"]:
        for sid, e in result["flight_errors"].items():
            print(f"warning: {sid}: {e}", file=sys.stderr)
    n = len(result["folds"][0]["rows"]) * 2
    print(f"# Vehicle calibration ({n} scenarios on the bare front-seat at speed-up {args.speedup:g}; "
          f"{result['flown_s']:.0f} s flying what was missing; work in {result['work']})\n")  # fmt: skip
    print(report(result))
    print(fitted_table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
