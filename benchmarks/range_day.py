"""A range day on ArduSub's real firmware (issue 38): calibrate the vehicle, re-plan for it, fly the new plan.

For each vehicle configuration (:data:`CONFIGS`: SITL parameters that change the vehicle),
flown from cold boots at ``--speedup`` as a range would:

1. **Morning.**  The calibration run (``rapt-plan shakedown MISSION --out DIR``) flown on the
   vehicle through ``rapt-plan run --mavlink``'s machinery (:func:`planner.fly.vehicle.run.run_vehicle`).
2. **Noon.**  While the morning flies: ``rapt-plan calibrate MISSION shakedown.mcap``, and ``rapt-plan
   compare`` of the committed plan's flights with that vehicle.  At noon, timed together (the noon step):
   ``rapt-plan calibrate MISSION shakedown.mcap FIVE_PLAN_LOGS --bias comparison.json --out calibrated.toml``,
   then ``rapt-plan generate calibrated.toml --budget 20000 --refine``.
3. **Afternoon.**  Every scenario of the new plan flown, each side as its robust "M" variant
   where the plan made one (the scenarios a range flies); then ``rapt-plan compare``.  Beside it, on
   its own copy of the plan, the afternoon conducted run by run (``--stages conducted``): ``rapt-plan
   next`` after every run names the next one, for at most :data:`CONDUCTED_RUNS` runs.
4. **Side by side.**  The committed plan (``field_plans/range2017``) flown on the same vehicle
   and compared: with the plan's vehicle, and re-predicted with the calibrated one.

The figures: the calibration run re-predicted by its own calibration (path RMS, energy);
the committed plan's scenarios re-predicted with the calibrated vehicle (median path RMS,
energy); pairs observed as predicted and predicted modes held, for the re-plan and for the
committed plan; the day's Brier score; the noon step's wall time.

Run:  ARDUSUB_SITL=../shared/ardusub/ardusub python benchmarks/range_day.py
      [--configs bluerov2,limited,current,cross] [--speedup 40] [--budget 20000] [--work DIR]
      [--stages committed,day,conducted] [--quick]

``--work`` keeps every log and row; run again with it and only what is missing is flown or
computed.  ``--quick``: one configuration, a 4,000-run re-plan and its first four scenarios
(``--refine`` spends 1,600 of its runs; a 2,000-run budget would leave the search under two batches).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from ardusub import NOT_AN_END, fly  # noqa: E402  benchmarks/ardusub.py, beside this script

MISSION = ROOT / "examples" / "range2017.toml"
COMMITTED = ROOT / "field_plans" / "range2017" / "plan.json"
#: A BlueROV2's pack (Ah): what the vehicle on the range carries (SITL's default is 3.3 Ah).
PACK_AH = 18.0
#: The vehicles flown: name -> (what it is, SITL parameters beyond the pack, the pack in Ah).  ArduPilot's
#: libraries/SITL/SIM_Submarine.cpp maps each thruster's PWM to thrust and current; limiting the
#: motors' PWM range (as a range does to protect ESCs or save the pack) makes a slower vehicle
#: that draws less.  SITL's default wind profile (SIM_WIND_T 0, scaled by the square root of the
#: altitude) is zero below the surface; with SIM_WIND_T 1 (no altitude limit) SIM_WIND_SPD acts at
#: every depth, and SIM_Submarine.cpp drags the hull on its water-relative velocity: the disarmed
#: vehicle drifts off its start, the velocity loop works up-current and the speed made good falls.
#: SIM_WIND_DIR is where the current comes from (225: it sets to the north-east, as the 2017 range's
#: flood tide did).
CONFIGS: dict[str, tuple[str, dict[str, float], float]] = {
    "bluerov2": ("BlueROV2, 18 Ah pack", {}, PACK_AH),
    "limited": (
        "BlueROV2, 18 Ah pack, thrusters limited to 1250-1750 us",
        {"MOT_PWM_MIN": 1250.0, "MOT_PWM_MAX": 1750.0},
        PACK_AH,
    ),
    "current": (
        "BlueROV2, 12 Ah pack, in a 0.3 m/s current from the south-west at every depth",
        {"SIM_WIND_T": 1.0, "SIM_WIND_SPD": 0.3, "SIM_WIND_DIR": 225.0, "SIM_WIND_TURB": 0.0},
        12.0,
    ),
    # a vehicle and water none of the others is: slower thrusters, a mid-size pack, a current across the flood
    "cross": (
        "BlueROV2, 15 Ah pack, thrusters limited to 1300-1700 us, in a 0.25 m/s current from the south-east",
        {
            "MOT_PWM_MIN": 1300.0,
            "MOT_PWM_MAX": 1700.0,
            "SIM_WIND_T": 1.0,
            "SIM_WIND_SPD": 0.25,
            "SIM_WIND_DIR": 135.0,
            "SIM_WIND_TURB": 0.0,
        },
        15.0,
    ),  # fmt: skip
}


def rapt_plan(*args: str) -> subprocess.CompletedProcess:
    """``rapt-plan ARGS`` in a subprocess (this checkout's code), its output captured."""
    cmd = [sys.executable, "-m", "planner.cli", *args]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=None)


def cached(path: Path, make) -> dict:
    """A row kept in ``path`` (JSON); made once per ``--work`` directory."""
    if path.is_file():
        return json.loads(path.read_text())
    row = make()
    if "error" not in row:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(row, indent=1))
    return row


def fly_plan(
    plan: Path, ids: list[str], out: Path, speedup: float, params: dict[str, float], pack_ah: float = PACK_AH
) -> list[dict]:
    """Every scenario ``ids`` of ``plan`` from a cold boot, logs in ``out``; rows cached beside them."""
    rows = []
    for sid in ids:
        log = out / f"{sid}.mcap"

        def make(sid=sid, log=log) -> dict:
            log.parent.mkdir(parents=True, exist_ok=True)
            return fly(sid, speedup, log, None, pack_ah, plan=plan, parameters=params)

        rows.append(cached(out / f"{sid}.json", make))
        print(
            f"    {plan.parent.name}/{sid}: {rows[-1].get('ended') or rows[-1].get('error')}",
            file=sys.stderr,
            flush=True,
        )
    return rows


def flown_ids(plan: Path) -> list[str]:
    """The scenarios a range flies from ``plan``: each pair side as its robust variant where there is one."""
    doc = json.loads(plan.read_text())
    variant_of = {v["variant_of"]: v["id"] for v in doc.get("variants", [])}
    return [variant_of.get(sid, sid) for pair in doc["pairs"] for sid in pair["scenarios"]]


def ended_by_scenario(row: dict) -> bool:
    return "error" not in row and not row["ended"].startswith(NOT_AN_END)


#: Watchdog reasons that mean our rig fell behind the firmware, not what the vehicle did: such a
#: flight is flown again (once) rather than counted.
RIG_FAILURES = ("watchdog: link_lost", "watchdog: stale_commands")


def refly_rig_failures(out: Path) -> None:
    """Forget the cached rows of flights our rig lost (a loaded machine at a high speed-up), so they fly again."""
    for path in out.glob("*.json"):
        if json.loads(path.read_text()).get("ended", "").startswith(RIG_FAILURES):
            path.unlink()


def morning(work: Path, speedup: float, params: dict[str, float], pack_ah: float = PACK_AH) -> dict:
    """The calibration run designed for the mission and flown on the vehicle."""
    design = work / "shakedown"
    if not (design / "plan.json").is_file():
        proc = rapt_plan("shakedown", str(MISSION), "--out", str(design))
        if proc.returncode:
            return {"error": proc.stdout + proc.stderr}
    (row,) = fly_plan(design / "plan.json", ["shakedown"], work / "morning", speedup, params, pack_ah)
    return row


#: Plan logs of the morning the noon step calibrates on beside the calibration run (the issue's range day: five).
NOON_PLAN_LOGS = 5


def morning_fit(work: Path) -> dict:
    """What the morning does while its plan flies: calibrate on the calibration run's log alone, then compare the
    morning's flights of the committed plan with that vehicle (the day's water and noise).  Timed, not noon's."""

    def make() -> dict:
        t0 = time.perf_counter()
        shakedown = str(work / "morning" / "shakedown.mcap")
        out = work / "morning_calibrated.toml"
        cal = rapt_plan("calibrate", str(MISSION), shakedown, "--out", str(out))
        if cal.returncode:
            return {"error": cal.stdout + cal.stderr}
        row: dict = {"calibrate_s": time.perf_counter() - t0, "calibrate_out": cal.stdout}
        logs = sorted(str(p) for p in (work / "committed").glob("*.mcap"))
        if logs:
            t0 = time.perf_counter()
            cmp = rapt_plan("compare", str(COMMITTED.parent), *logs, "--calibrated", str(out), "--out",
                            str(work / "morning_comparison"), "--dithers", "0")  # fmt: skip
            if cmp.returncode:
                return {"error": cmp.stdout + cmp.stderr}
            row["compare_s"] = time.perf_counter() - t0
        return row

    return cached(work / "morning_fit.json", make)


def noon(work: Path, budget: int) -> dict:
    """The noon step, timed as a whole: calibrate on the calibration run's log and the morning's first
    :data:`NOON_PLAN_LOGS` plan logs in the day's water the morning's comparison found (``--bias``: its water and
    execution noise, which the re-plan dithers by; the speed loop the morning's calibration chose), then re-plan on
    the calibrated mission.  Without a morning comparison: calibrate on the calibration run alone."""

    def make() -> dict:
        started = time.perf_counter()
        out = work / "calibrated.toml"
        logs = [str(work / "morning" / "shakedown.mcap")]
        comparison = work / "morning_comparison" / "comparison.json"
        extra: list[str] = []
        if comparison.is_file():
            logs += sorted(str(p) for p in (work / "committed").glob("*.mcap"))[:NOON_PLAN_LOGS]
            extra = ["--bias", str(comparison)]
        cal = rapt_plan("calibrate", str(MISSION), *logs, *extra, "--out", str(out))
        if cal.returncode:
            return {"error": cal.stdout + cal.stderr}
        row: dict = {"calibrate_s": time.perf_counter() - started, "calibrate_out": cal.stdout, "logs": len(logs)}
        t0 = time.perf_counter()
        gen = rapt_plan("generate", str(out), "--out", str(work / "plan"), "--budget", str(budget), "--refine")
        if gen.returncode:
            return {"error": gen.stdout + gen.stderr}
        row["generate_s"] = time.perf_counter() - t0
        row["generate_out"] = gen.stdout
        row["noon_s"] = time.perf_counter() - started
        return row

    return cached(work / "noon.json", make)


#: Runs the conducted afternoon may spend (the issue's range day: at most 14).
CONDUCTED_RUNS = 14


def next_answer(plan_dir: Path, logs: list[str], runs_left: int) -> tuple[dict, float]:
    """``rapt-plan next --json``'s answer, and the call's wall time."""
    t0 = time.perf_counter()
    proc = rapt_plan("next", str(plan_dir), *logs, "--runs-left", str(runs_left), "--json")
    took = time.perf_counter() - t0
    if proc.returncode:
        return {"error": proc.stdout + proc.stderr}, took
    return json.loads(proc.stdout.strip().splitlines()[-1]), took


def conducted(here: Path, speedup: float, params: dict[str, float], pack_ah: float, runs: int = CONDUCTED_RUNS) -> dict:
    """The afternoon conducted by ``rapt-plan next`` on its own copy of the noon plan (its moves are added there):
    fly what it names until it stops or :data:`CONDUCTED_RUNS` are spent.  Flights are cached; a rerun replays
    the same answers (the same seed and logs), flying only what is missing."""
    plan_dir = here / "conducted_plan"
    if not plan_dir.is_dir():
        shutil.copytree(here / "plan", plan_dir, ignore=shutil.ignore_patterns("afternoon.json"))
    out = here / "conducted"
    out.mkdir(parents=True, exist_ok=True)
    logs: list[str] = []
    row: dict = {"calls_s": [], "reasons": [], "flown": []}
    for k in range(1, runs + 1):
        answer, took = next_answer(plan_dir, logs, runs - k + 1)
        row["calls_s"].append(took)
        if "error" in answer:
            return {**row, "error": answer["error"]}
        row["reasons"].append(answer["reason"])
        if answer["next"] is None:
            break
        sid = answer["next"]["scenario"]
        stem = out / f"run{k:02d}_{sid}"
        for _ in range(2):  # a flight our rig lost is flown again, once
            flown = cached(stem.with_suffix(".json"), lambda sid=sid, stem=stem: fly(sid, speedup,
                           stem.with_suffix(".mcap"), None, pack_ah, plan=plan_dir / "plan.json",
                           parameters=params))  # fmt: skip
            if "error" not in flown and not flown["ended"].startswith(RIG_FAILURES):
                break
            stem.with_suffix(".json").unlink(missing_ok=True)
        print(f"    conducted run {k}: {sid}: {flown.get('ended') or flown.get('error')}", file=sys.stderr, flush=True)
        row["flown"].append(sid)
        logs.append(str(stem.with_suffix(".mcap")))
    final, took = next_answer(plan_dir, logs, 0)
    fixed, _ = next_answer(here / "plan", sorted(str(p) for p in (here / "afternoon").glob("*.mcap")), 0)
    row.update(final=final, fixed=fixed, runs=len(logs), fixed_runs=len(list((here / "afternoon").glob("*.mcap"))))
    return row


def next_timing(here: Path, runs: int = CONDUCTED_RUNS) -> list[float]:
    """``rapt-plan next``'s wall time per call, measured alone: the conducted afternoon's calls made again on a
    fresh copy of the noon plan, each with the logs flown before it (the same answers: the same seed and logs)."""
    logs = sorted(str(p) for p in (here / "conducted").glob("run*.mcap"))
    plan_dir = here / "timing_plan"
    shutil.rmtree(plan_dir, ignore_errors=True)
    shutil.copytree(here / "plan", plan_dir, ignore=shutil.ignore_patterns("afternoon.json"))
    times = []
    for k in range(len(logs) + 1):
        answer, took = next_answer(plan_dir, logs[:k], runs - k)
        if "error" in answer:
            raise RuntimeError(answer["error"])
        times.append(took)
    return times


def confirmed(answer: dict) -> str:
    """Boundaries confirmed of the plan's: a new pair next wrote counts for the one it replaces."""
    pairs = answer.get("pairs", [])
    done = {p.get("replaces", p["id"]) for p in pairs if p["status"] == "confirmed"}
    boundaries = [p["id"] for p in pairs if "replaces" not in p]
    return f"{sum(b in done for b in boundaries)} of {len(boundaries)}"


def conducted_report(row: dict) -> list[str]:
    """The conducted afternoon beside the fixed one, as markdown lines."""
    calls = sorted(row["calls_s"])
    out = [f"- afternoon, each side once ({row['fixed_runs']} runs): boundaries confirmed {confirmed(row['fixed'])}",
           f"- afternoon conducted by `next` ({row['runs']} runs): boundaries confirmed {confirmed(row['final'])}; "
           f"`next` per call: median {calls[len(calls) // 2]:.1f} s, max {calls[-1]:.1f} s",
           "", "  Its answers, in order:", ""]  # fmt: skip
    out += [f"  {i + 1}. {reason}" for i, reason in enumerate(row["reasons"])]
    return out + [""]


def compare(plan: Path, logs: Path, out: Path, *extra: str) -> dict | None:
    """``rapt-plan compare`` on every log in ``logs``; its comparison.json (None when it failed, or when nothing was
    flown there: ``--stages day`` flies no committed scenario)."""
    done = out / "comparison.json"
    if not done.is_file():
        mcaps = sorted(str(p) for p in logs.glob("*.mcap"))
        if not mcaps:
            return None
        proc = rapt_plan("compare", str(plan.parent), *mcaps, "--out", str(out), *extra)
        if proc.returncode:
            print(proc.stdout + proc.stderr, file=sys.stderr)
            return None
    return json.loads(done.read_text())


def track_errors(mission, u, run, driver=None, plant=None) -> tuple[float, float]:
    """RMS path error (m) of ``run``'s logged track against ``mission``'s prediction of row ``u`` (at the same
    times), and the energy used by the log's last step as a share of the logged energy (predicted / logged - 1).
    ``plant`` flies in ``mission``'s water while the autonomy believes ``mission.vehicle``."""
    import numpy as np

    import sim.uuv

    row = np.asarray(u, float)[None, :]
    pred = sim.uuv.simulate(mission, row, trajectories=True, driver=driver, plant=plant).trajectory(0)
    track = run.steps
    if pred is None or not track.shape[0]:
        return float("nan"), float("nan")
    t = np.clip(track[:, 0], pred[0, 0], pred[-1, 0])
    px, py = np.interp(t, pred[:, 0], pred[:, 1]), np.interp(t, pred[:, 0], pred[:, 2])
    rms = float(np.sqrt(np.mean((track[:, 1] - px) ** 2 + (track[:, 2] - py) ** 2)))
    used = track[-1, 4] - track[0, 4]
    predicted = np.interp(t[-1], pred[:, 0], pred[:, 4]) - np.interp(t[0], pred[:, 0], pred[:, 4])
    return rms, float(predicted / used - 1.0) if used > 0 else float("nan")


def repredictions(here: Path) -> dict:
    """The calibration run and the committed plan's flights re-predicted with the calibrated vehicle in the
    calibrated file's water, their back-seat believing the vehicle and tide table it flew with."""
    import numpy as np

    import sim.uuv
    from planner.common.plans import load_plan
    from planner.review.logs import read_run
    from sim.uuv.legs import leg_driver, legs_from_json

    calibrated = sim.uuv.load_mission(here / "calibrated.toml")
    design = load_plan(here / "shakedown" / "plan.json")
    entry = design.scenario("shakedown")
    run = read_run(here / "morning" / "shakedown.mcap")
    driver = leg_driver(legs_from_json(entry["legs"]))
    flown = in_the_days_water(design.mission, calibrated)
    plant = gauge_of(design.mission, calibrated.vehicle)
    out = {"shakedown": dict(zip(("path_m", "energy"), track_errors(flown, entry["u"], run, driver, plant)))}
    out["shakedown_before"] = dict(zip(("path_m", "energy"), track_errors(design.mission, entry["u"], run, driver)))
    committed = load_plan(COMMITTED)
    rows = []
    for log in sorted((here / "committed").glob("*.mcap")):
        sid = log.stem
        run = read_run(log)
        before = track_errors(committed.mission, committed.u(sid), run)
        flown, plant = in_the_days_water(committed.mission, calibrated), gauge_of(committed.mission, calibrated.vehicle)
        after = track_errors(flown, committed.u(sid), run, plant=plant)
        rows.append({"scenario": sid, "path_before_m": before[0], "path_after_m": after[0],
                     "energy_before": before[1], "energy_after": after[1]})  # fmt: skip
    out["committed"] = rows
    out["median_path_after_m"] = float(np.median([r["path_after_m"] for r in rows])) if rows else None
    out["median_abs_energy_after"] = float(np.median([abs(r["energy_after"]) for r in rows])) if rows else None
    return out


def gauge_of(mission, vehicle):
    """``vehicle``'s dynamics and power with the battery the flights' virtual gauge counted from: ``mission``'s."""
    import dataclasses

    return dataclasses.replace(vehicle, battery_wh=mission.vehicle.battery_wh)


def in_the_days_water(mission, calibrated):
    """``mission`` (its autonomy, tide table and vehicle as flown) in the water the calibrated file measured."""
    import dataclasses

    return dataclasses.replace(
        mission, execution_bias=calibrated.execution_bias, execution_bias_source=calibrated.execution_bias_source
    )


def pct(v) -> str:
    return "-" if v is None or v != v else f"{100 * v:+.1f} %"


def num(v, fmt: str = ".0f") -> str:
    return "-" if v is None or v != v else format(v, fmt)


def modes_held(comparison: dict) -> tuple[int, int]:
    """Scenarios whose observed mode is the plan's predicted one, of those with an observed mode."""
    rows = [r for r in comparison["scenarios"] if r["observed_mode"] is not None]
    return sum(r["observed_mode"] == r["predicted_mode"] for r in rows), len(comparison["scenarios"])


def pairs_held(comparison: dict) -> tuple[int, int]:
    return sum(bool(p.get("observed_as_predicted")) for p in comparison["pairs"]), len(comparison["pairs"])


def report(
    name: str, here: Path, fit: dict | None, timing: dict | None, rep: dict | None, day: dict | None, base: dict | None
) -> str:
    """One vehicle's figures as markdown."""
    out = [f"## {name}: {CONFIGS[name][0]}", ""]
    if rep is not None:
        sh, b = rep["shakedown"], rep["shakedown_before"]
        out += [
            f"Calibration run re-predicted: path RMS {num(b['path_m'])} m -> {num(sh['path_m'], '.1f')} m, "
            f"energy {pct(b['energy'])} -> {pct(sh['energy'])} (file's vehicle -> calibrated).",
            "",
            "| committed scenario | path RMS, plan's vehicle (m) | calibrated (m) | energy, plan's | calibrated |",
            "|---|---|---|---|---|",
        ]
        for r in rep["committed"]:
            out.append(f"| {r['scenario']} | {num(r['path_before_m'])} | {num(r['path_after_m'], '.1f')} | "
                       f"{pct(r['energy_before'])} | {pct(r['energy_after'])} |")  # fmt: skip
        out += ["", f"Median path RMS with the calibrated vehicle: {num(rep['median_path_after_m'], '.1f')} m; "
                f"median |energy error| {pct(rep['median_abs_energy_after'])}.", ""]  # fmt: skip
    if fit is not None:
        parts = [f"calibrate on the calibration run {fit['calibrate_s']:.0f} s"]
        if "compare_s" in fit:
            parts.append(f"compare of the committed flights {fit['compare_s']:.0f} s")
        out += [f"Morning, while the plan flies: {', '.join(parts)}.", ""]
    if timing is not None:
        parts = [f"calibrate on {timing.get('logs', 1)} log(s) {timing['calibrate_s']:.0f} s",
                 f"generate {timing.get('generate_s', 0):.0f} s"]  # fmt: skip
        out += [f"Noon step ({timing.get('budget', '?')}-run re-plan): {timing['noon_s']:.0f} s ({', '.join(parts)}).",
                ""]  # fmt: skip
    for label, comp in (("re-plan", day), ("committed plan", base)):
        if comp is None:
            continue
        m, n = modes_held(comp)
        p, q = pairs_held(comp)
        scores = comp.get("forecast", {}).get("brier", {})
        brier, det = scores.get("corrected", {}), scores.get("deterministic_corrected", {})
        assumed = scores.get("corrected_assumed_noise", {})
        out.append(f"- {label}: pairs observed as predicted {p}/{q}; predicted mode held {m}/{n}; "
                   f"Brier (corrected forecast) modes {num(brier.get('mode'), '.2f')}, held {num(brier.get('held'), '.2f')} "
                   f"(plan's assumed noise: held {num(assumed.get('held'), '.2f')}; deterministic correction: held "
                   f"{num(det.get('held'), '.2f')})")  # fmt: skip
    planned = here / "plan" / "plan.json"
    if planned.is_file():
        doc = json.loads(planned.read_text())
        ps = [pr.get("p_straddle") for pr in doc["pairs"]]
        high = sum(1 for v in ps if v is not None and v >= 0.8)
        cannot = doc["study"].get("unreached") or {}
        out.append(f"- re-plan: P(straddle) planned {', '.join(num(v, '.2f') for v in ps)} ({high} of {len(ps)} "
                   f">= 0.8); flown sides at most {num(max(pr.get('flown_distance', 0) for pr in doc['pairs']), '.3f')} "
                   f"apart; unreached: {', '.join(cannot.get('modes', [])) or 'none'}")  # fmt: skip
    out.append("")
    return "\n".join(out)


def the_day(name: str, here: Path, args, params: dict[str, float], pack_ah: float) -> bool:
    """The morning, the noon step and the fixed afternoon of one vehicle, then its report; False when a stage failed."""
    refly_rig_failures(here / "morning")
    row = morning(here, args.speedup, params, pack_ah)
    if "error" in row or not ended_by_scenario(row):
        print(f"  {name}: the calibration run did not finish: {row.get('error') or row['ended']}", file=sys.stderr)
        return False
    fit = morning_fit(here)
    if "error" in fit:
        print(f"  {name}: the morning's calibration failed: {fit['error']}", file=sys.stderr)
        return False
    budget = 4000 if args.quick else args.budget
    timing = noon(here, budget)
    if "error" in timing:
        print(f"  {name}: noon step failed: {timing['error']}", file=sys.stderr)
        return False
    ids = flown_ids(here / "plan" / "plan.json")
    refly_rig_failures(here / "afternoon")
    plan = here / "plan" / "plan.json"
    fly_plan(plan, ids[:4] if args.quick else ids, here / "afternoon", args.speedup, params, pack_ah)
    timing["budget"] = budget
    day = compare(plan, here / "afternoon", here / "comparison")
    base = compare(COMMITTED, here / "committed", here / "committed_comparison")
    rep = repredictions(here) if (here / "committed").is_dir() else None
    print(report(name, here, fit, timing, rep, day, base), flush=True)
    return True


def main(argv: list[str] | None = None) -> int:
    from planner.fly.ardusub_sitl import ENV, sitl_binary

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", default=",".join(CONFIGS), help=f"Vehicles to fly ({', '.join(CONFIGS)}).")
    ap.add_argument("--speedup", type=float, default=40.0)
    ap.add_argument("--budget", type=int, default=20000, help="Runs in the re-plan's search.")
    ap.add_argument(
        "--stages",
        default="committed,day,conducted",
        help="committed (the committed plan), day (the loop), conducted (the afternoon run by run by next), "
        "timing (next's calls of the conducted afternoon made again, alone, and timed; not by default).",
    )
    ap.add_argument("--work", type=Path, default=None, help="Directory for logs, plans and rows (resumable).")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if sitl_binary() is None:
        print(
            f"error: {ENV} is not set; point it at the ArduSub SITL binary (../shared/ardusub/ardusub)", file=sys.stderr
        )
        return 2
    configs = [c.strip() for c in args.configs.split(",") if c.strip()]
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown:
        print(f"error: --configs: unknown {unknown[0]!r}; choose from {', '.join(CONFIGS)}", file=sys.stderr)
        return 2
    work = args.work or Path(tempfile.mkdtemp(prefix="rapt_range_day_"))
    stages = set(args.stages.split(","))
    committed_ids = [s["id"] for s in json.loads(COMMITTED.read_text())["scenarios"]]
    for name in configs[:1] if args.quick else configs:
        _, params, pack_ah = CONFIGS[name]
        print(f"  {name}: {CONFIGS[name][0]}", file=sys.stderr, flush=True)
        here = work / name
        if "committed" in stages:
            refly_rig_failures(here / "committed")
            fly_plan(
                COMMITTED,
                committed_ids[:4] if args.quick else committed_ids,
                here / "committed",
                args.speedup,
                params,
                pack_ah,
            )
        if "day" in stages and not the_day(name, here, args, params, pack_ah):
            continue
        if "conducted" in stages and (here / "plan" / "plan.json").is_file():
            row = conducted(here, args.speedup, params, pack_ah)
            if "error" in row:
                print(f"  {name}: the conducted afternoon failed: {row['error']}", file=sys.stderr)
                continue
            print("\n".join([f"## {name}: the afternoon conducted", ""] + conducted_report(row)), flush=True)
        if "timing" in stages and (here / "conducted").is_dir():
            calls = next_timing(here)
            t = sorted(calls)
            print(f"- {name}: `next` alone, {len(t)} calls: median {t[len(t) // 2]:.1f} s, max {t[-1]:.1f} s "
                  f"(the first, which reads the noon study: {calls[0]:.1f} s)", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
