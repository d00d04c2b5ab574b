"""The range day rehearsed on ArduSub's real firmware (issue 28): plan on the model, fly SITL, compare, correct.

Every flight boots ArduSub SITL cold (``planner.fly.ardusub_sitl.ArduSubSitl``: a wiped parameter
store, its home at range2017's launch point) and flies one scenario of
``field_plans/range2017/`` through :func:`planner.fly.vehicle.run.run_vehicle` — what
``rapt-plan run PLAN --scenario ID --mavlink tcp:...`` does on a range day: bring-up (the
estimator awaited, GUIDED retried until accepted, armed only in GUIDED), the vehicle-paced
back-seat, the virtual sonar and fuel gauge, the watchdog (no-go areas record-only: they are
virtual, and the plan predicts some scenarios to cross one), the referee, the MCAP log.

1. **Speed-up sweep.**  The first scenario's first ``--sweep-s`` vehicle seconds (after the
   bring-up) at each speed-up; our side keeps up when no decision period passes without a
   decision, the watchdog never takes over for stale set-points and no velocity target
   lapses.  A lapse is a gap of more than ArduSub's 3 s (``GUIDED_POSVEL_TIMEOUT_MS``, see
   ArduSub/mode_guided.cpp) between set-points reaching the firmware, in its own clock:
   each set-point's publication time in the log is mapped to the vehicle's ``time_boot_ms``
   through the telemetry logged around it.
2. **Scenarios.**  ``--scenarios`` scenarios flown to their end condition at the highest
   speed-up that kept up (or ``--speedup``): boot-to-armed time, how the run ended, watchdog
   interventions, observed (the logged track scored by the mission's scorer) versus the
   plan's predicted mode, RMS path error against the plan's predicted track, decision latency
   p50/p99 (position report in -> set-point out, wall ms) and set-points that lapsed.
   SITL's BlueROV2 draws about 35 A at the thrust the plan's speeds ask for: its default
   3.3 Ah pack (and an 18 Ah BlueROV2 pack) reaches our watchdog's critical 10 % long before a
   45-minute scenario ends.  The scenarios are flown on a :data:`REHEARSAL_PACK_AH` pack so
   that the scenario's own ends apply; the first scenario is flown again on both real packs.
   No failsafe is changed: ArduSub's stay as shipped, our watchdog's pack limit stays 10 %.
3. **Calibration.**  ``rapt-plan calibrate`` (issue 23) on one half of the logs (pair*a, then
   pair*b), and the execution-bias fit of ``rapt-plan compare`` on the same half flying the
   calibrated vehicle; the other half predicted before calibration, after it, and after it
   with the fitted bias, set against what the firmware did.

The firmware's BlueROV2 is not the planner's vehicle (asked for 1 m/s it makes about 0.72; the
mission assumes a 2 m/s cruise): how many predicted modes hold is the figure a range needs.

Run:  ARDUSUB_SITL=../shared/ardusub/ardusub python benchmarks/ardusub.py
      [--speedups 10,20,30,40] [--speedup S] [--scenarios 10] [--work DIR] [--quick]

``--work`` keeps the logs; run again with it and only the scenarios missing there are flown.
``--quick``: speed-up 20 alone for 300 vehicle seconds, two scenarios cut at 600 vehicle
seconds, no calibration (about two minutes).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
#: ArduSub drops a GUIDED velocity target it has not had refreshed for this long (vehicle ms).
VELOCITY_TIMEOUT_MS = 3000
#: Watchdog reasons logged without taking control: range2017's no-go areas are virtual.
RECORD_ONLY = ("nogo",)
#: The pack a range's BlueROV2 carries (Ah); SITL's default is a 3.3 Ah pack.
BLUEROV2_PACK_AH = 18.0
#: A pack that outlasts a 45-minute scenario at SITL's full-thrust draw (about 35 A), so that
#: the scenario's own ends (its virtual battery, clock, recovery) end each run as the plan models.
REHEARSAL_PACK_AH = 100.0
#: Vehicle seconds a cold boot's bring-up takes (the EKF uses GPS about 43 s after boot; then the dive).
BRINGUP_S = 120.0
#: How runs end that the scenario did not end: the watchdog, a wall-time cut, the operator, the vehicle.
NOT_AN_END = ("watchdog:", "wall-time", "stopped", "vehicle:")
#: Watchdog reasons that mean our side fell behind (the others are the vehicle's or the scenario's).
OURS = ("stale_commands",)


def pack_parameters(ah: float) -> dict[str, float]:
    """SITL parameters giving the simulated vehicle an ``ah`` pack (0: the firmware's default pack)."""
    return {} if ah <= 0 else {"BATT_CAPACITY": 1000.0 * ah, "SIM_BATT_CAP_AH": ah}


def setpoint_gaps(log: Path, vehicle: str = "uuv1") -> np.ndarray:
    """Vehicle-clock gaps (ms) between consecutive set-points of the scenario, as the firmware received them.

    A set-point's arrival is its publication's log time mapped to ``time_boot_ms`` by
    interpolating the position reports logged around it (wall -> vehicle clock).
    """
    from bridge.logger import read_log

    clock_wall, clock_ms, sent = [], [], []
    for topic, t_ns, payload in read_log(log):
        if topic == f"rapt/{vehicle}/mavlink/GLOBAL_POSITION_INT":
            clock_wall.append(t_ns)
            clock_ms.append(payload["time_boot_ms"])
        elif topic.startswith(f"rapt/{vehicle}/command/") and isinstance(payload, dict) and "vx" in payload:
            sent.append(t_ns)
    if len(sent) < 2 or len(clock_wall) < 2:
        return np.zeros(0)
    order = np.argsort(clock_wall)
    at = np.interp(np.asarray(sent, float), np.asarray(clock_wall, float)[order], np.asarray(clock_ms, float)[order])
    return np.diff(np.sort(at))


def fly(
    sid: str,
    speedup: float,
    log: Path,
    vehicle_s: float | None = None,
    pack_ah: float = REHEARSAL_PACK_AH,
    *,
    plan: Path = PLAN,
    parameters: dict[str, float] | None = None,
) -> dict:
    """One scenario of ``plan`` from a cold boot of the firmware; ``vehicle_s`` cuts the flight after that much
    vehicle time; ``parameters`` are more SITL parameters (the vehicle or the water: see benchmarks/range_day.py)."""
    from planner.fly.ardusub_sitl import ArduSubSitl, launch_point
    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.run import run_vehicle
    from rapt.errors import RaptError

    flight = flight_from_plan(plan, sid)
    limit = flight.mission.time_limit_s + 600.0 if vehicle_s is None else vehicle_s
    row: dict = {"scenario": sid, "speedup": speedup, "log": str(log), "pack_ah": pack_ah}
    started = time.perf_counter()
    try:
        params = {**pack_parameters(pack_ah), **(parameters or {})}
        with ArduSubSitl(launch_point(flight.mission), speedup=speedup, parameters=params) as sitl:
            booted = time.perf_counter()
            result = run_vehicle(
                flight,
                sitl.connection,
                log_path=log,
                record_only=RECORD_ONLY,
                timeout_s=(limit + BRINGUP_S) / speedup + 5,
            )
    except RaptError as exc:
        row["error"] = str(exc)
        return row
    arm = next((s for s in result.timeline if s.name == "arm" and s.status == "ok"), None)
    gaps = setpoint_gaps(log)
    b = result.bridge_stats
    row.update(
        ended=result.ended,
        watchdog=result.watchdog,
        violations=sorted(result.violations),
        sim_s=result.sim_s,
        wall_s=time.perf_counter() - started,
        armed_vehicle_s=None if arm is None or arm.time_boot_ms is None else arm.time_boot_ms / 1000.0,
        armed_wall_s=None if arm is None else booted - started + arm.wall_s,
        latency_ms_p50=result.decisions["latency_ms_p50"],
        latency_ms_p99=result.decisions["latency_ms_p99"],
        decisions=result.decisions["decisions"],
        missed=result.decisions["missed"],
        stale=result.decisions["stale"],
        max_gap_ms=float(gaps.max()) if gaps.size else None,
        lapsed=int(np.sum(gaps > VELOCITY_TIMEOUT_MS)),
        refused=int(b.get("commands_in", 0) - b.get("commands_forwarded", 0)),
    )
    row["kept_up"] = not row["missed"] and row["watchdog"] not in OURS and not row["lapsed"] and row["decisions"] > 0
    return row


def _cached(work: Path, name: str, make) -> dict:
    """A row kept in ``work/name.json`` (a later run with the same ``--work`` flies only what is missing)."""
    path = work / f"{name}.json"
    if path.is_file():
        return json.loads(path.read_text())
    row = make()
    if "error" not in row:
        path.write_text(json.dumps(row, indent=1))
    return row


def sweep(work: Path, sid: str, speedups: list[float], vehicle_s: float) -> list[dict]:
    rows = []
    for s in speedups:
        rows.append(_cached(work, f"sweep_{s:g}", lambda s=s: fly(sid, s, work / f"sweep_{s:g}.mcap", vehicle_s)))
        print(f"  sweep x{s:g}: {_verdict(rows[-1])}", file=sys.stderr, flush=True)
    return rows


def _verdict(row: dict) -> str:
    if "error" in row:
        return row["error"]
    return "kept up" if row["kept_up"] else "fell behind"


def highest_kept_up(rows: list[dict]) -> float | None:
    """The highest speed-up of the sweep at which our side kept up at it and every lower one."""
    best = None
    for r in sorted(rows, key=lambda r: r["speedup"]):
        if not r.get("kept_up"):
            break
        best = r["speedup"]
    return best


def observe(rows: list[dict]) -> None:
    """Add observed mode (the logged track scored) and path error against the plan's prediction to each row."""
    import sim.uuv
    from benchmarks.calibrate import observed_mode, path_rms
    from planner.common.plans import load_plan
    from planner.review.logs import read_run

    plan = load_plan(PLAN)
    flown = [r for r in rows if "error" not in r]
    if not flown:
        return
    U = np.array([plan.u(r["scenario"]) for r in flown])
    pred = sim.uuv.simulate(plan.mission, U, trajectories=True)
    for i, r in enumerate(flown):
        run = read_run(Path(r["log"]))
        r["predicted"] = plan.scenario(r["scenario"])["predicted"]["mode"]
        cut = r["ended"].startswith(NOT_AN_END)  # a run the scenario did not end has no mode to observe
        r["observed"] = None if cut else observed_mode(plan.mission, plan.u(r["scenario"]), run)
        r["path_rms_m"] = path_rms(run.track, pred.trajectory(i))


def calibration(rows: list[dict], work: Path, seed: int = 0) -> dict:
    """Calibrate (and fit the bias) on one half, predict the other; both ways round."""
    import sim.uuv
    from benchmarks.calibrate import evaluate
    from planner.common.plans import load_plan
    from planner.review.compare import compare
    from planner.review.runs import CompareConfig
    from sim.uuv.bias import Bias
    from sim.uuv.scoring import MODE_NAMES

    plan = load_plan(PLAN)
    logs = {r["scenario"]: Path(r["log"]) for r in rows if "error" not in r and r.get("observed") is not None}
    result = evaluate(PLAN, logs, work, seed)
    for k, fold in enumerate(result["folds"]):
        vehicle = sim.uuv.load_mission(work / f"calibrated_{k + 1}.toml").vehicle
        comp = compare(
            PLAN, [logs[s] for s in fold["fit_on"]], None, CompareConfig(dithers=0, bootstrap=0, plant=vehicle)
        )
        # the bias compare applies: the fit, when leaving one log out showed it helps; neutral otherwise
        bias = Bias(**comp["correction"]["bias"])
        fold["bias"] = {n: v for n, v in bias.to_dict().items() if v != getattr(Bias(), n)}
        fold["bias_note"] = comp["correction"]["note"]
        U = np.array([plan.u(r["scenario"]) for r in fold["rows"]])
        biased = sim.uuv.simulate(plan.mission, U, bias=bias, plant=vehicle)
        for i, r in enumerate(fold["rows"]):
            r["after_bias"] = MODE_NAMES[biased.modes[i]]
    return result


def _took_over(row: dict) -> str:
    """The watchdog's reason when it ended the run (at the scenario's own end it surfaces the vehicle too)."""
    return row["watchdog"] if row["ended"].startswith("watchdog:") else "no"


def _head(*columns: str) -> list[str]:
    """A markdown table's header and rule."""
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def _f(v, fmt: str = ".0f") -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def _sweep_section(sweep_rows: list[dict], speedup: float | None) -> list[str]:
    """The speed-up sweep's table and the highest speed-up that kept up."""
    out = ["## Speed-up sweep (first scenario, cut short)", ""]
    out += _head("speed-up", "vehicle s", "decisions", "missed", "stale", "p50 ms", "p99 ms",
                 "p99 x speed-up (vehicle ms)", "longest set-point gap (vehicle ms)", "lapsed", "watchdog", "kept up")  # fmt: skip
    for r in sweep_rows:
        if "error" in r:
            out.append(f"| {r['speedup']:g} | {r['error']} |" + " |" * 10)
            continue
        p99 = r["latency_ms_p99"]
        out.append(
            f"| {r['speedup']:g} | {r['sim_s']:.0f} | {r['decisions']} | {r['missed']} | {r['stale']} | "
            f"{_f(r['latency_ms_p50'], '.1f')} | {_f(p99, '.1f')} | {_f(None if p99 is None else p99 * r['speedup'])} | "
            f"{_f(r['max_gap_ms'])} | {r['lapsed']} | {r['watchdog'] or 'no'} | {'yes' if r['kept_up'] else 'no'} |"
        )
    out += ["", f"Highest speed-up kept up: {_f(speedup, 'g')}.", ""]
    return out


def _scenario_section(rows: list[dict], speedup: float | None) -> list[str]:
    """The scenarios flown at ``speedup``: one row each, then how many ended and held their mode."""
    pack = rows[0]["pack_ah"] if rows else REHEARSAL_PACK_AH
    out = [f"## Scenarios at speed-up {_f(speedup, 'g')} ({pack:g} Ah pack: the scenario's own ends apply)", ""]
    out += _head("scenario", "boot to armed in GUIDED (vehicle s / wall s)", "ended", "vehicle s", "watchdog",
                 "predicted", "observed", "path RMS (m)", "p50 / p99 ms", "longest gap (vehicle ms)", "lapsed")  # fmt: skip
    for r in rows:
        if "error" in r:
            out.append(f"| {r['scenario']} | {r['error']} |" + " |" * 9)
            continue
        out.append(
            f"| {r['scenario']} | {_f(r['armed_vehicle_s'], '.1f')} / {_f(r['armed_wall_s'], '.1f')} | {r['ended']} | "
            f"{r['sim_s']:.0f} | {_took_over(r)} | {r.get('predicted', '-')} | "
            f"{r.get('observed') or 'no observation'} | {_f(r.get('path_rms_m'))} | "
            f"{_f(r['latency_ms_p50'], '.1f')} / {_f(r['latency_ms_p99'], '.1f')} | {_f(r['max_gap_ms'])} | {r['lapsed']} |"
        )
    flown = [r for r in rows if "error" not in r]
    ended = sum(not r["ended"].startswith(NOT_AN_END) for r in flown)
    held = sum(r.get("observed") is not None and r["observed"] == r.get("predicted") for r in flown)
    out += [
        "",
        f"Flown to the scenario's own end condition: {ended}/{len(rows)}; set-points lapsed: "
        f"{sum(r['lapsed'] for r in flown)}; the plan's predicted mode observed: {held}/{len(rows)}.",
        "",
    ]
    return out


def _pack_section(packs: list[dict]) -> list[str]:
    """The first scenario flown on the vehicle's own pack (firmware default or a given capacity)."""
    out = ["## The vehicle's own pack (first scenario)", ""]
    out += _head("pack", "ended", "vehicle s", "watchdog", "observed")
    for r in packs:
        pack = "firmware default (3.3 Ah)" if not r["pack_ah"] else f"{r['pack_ah']:g} Ah"
        if "error" in r:
            out.append(f"| {pack} | {r['error']} | | | |")
            continue
        out.append(
            f"| {pack} | {r['ended']} | {r['sim_s']:.0f} | {_took_over(r)} | {r.get('observed') or 'no observation'} |"
        )
    out.append("")
    return out


def _calibration_section(cal: dict) -> list[str]:
    """Held-out predictions before and after calibration, and the fitted parameters per fold."""
    from planner.review.vehicle_fit import FITTED

    out = ["## Held-out predictions before and after calibration", ""]
    out += _head("fitted on", "scenario", "observed", "predicted (plan's vehicle)", "calibrated",
                 "calibrated + bias", "path RMS before (m)", "after (m)")  # fmt: skip
    n = before = after = biased = 0
    for f in cal["folds"]:
        for r in f["rows"]:
            out.append(
                f"| {', '.join(f['fit_on'])} | {r['scenario']} | {r['observed'] or 'no observation'} | "
                f"{r['before']} | {r['after']} | {r['after_bias']} | {_f(r['path_before_m'])} | "
                f"{_f(r['path_after_m'])} |"
            )
            if r["observed"] is not None:
                n += 1
                before += r["before"] == r["observed"]
                after += r["after"] == r["observed"]
                biased += r["after_bias"] == r["observed"]
    out += [
        "",
        f"Predicted modes that hold on the held-out half: {before}/{n} before calibration, {after}/{n} after, "
        f"{biased}/{n} after calibration and the fitted bias.",
        "",
    ]
    out.append("| fold | " + " | ".join(FITTED) + " | bias |")
    out.append("|---|" + "---|" * (len(FITTED) + 1))
    for k, f in enumerate(cal["folds"]):
        cells = [f"{f['fitted'][n][0]:.3g}" + ("" if f["fitted"][n][2] else " (n.i.)") for n in FITTED]
        bias = ", ".join(f"{n} {v:.3g}" for n, v in f["bias"].items()) or "neutral"
        out.append(f"| {k + 1} | " + " | ".join(cells) + f" | {bias} |")
    file = cal["file"]
    out.append("| file | " + " | ".join(f"{file[n]:.3g}" for n in FITTED) + " | |")
    return out


def report(
    sweep_rows: list[dict], speedup: float | None, rows: list[dict], cal: dict | None, packs: list[dict] = ()
) -> str:
    out = _sweep_section(sweep_rows, speedup) + _scenario_section(rows, speedup)
    if packs:
        out += _pack_section(packs)
    if cal is not None:
        out += _calibration_section(cal)
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    from planner.common.plans import load_plan
    from planner.fly.ardusub_sitl import ENV, sitl_binary

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speedups", default="10,20,30,40", help="Speed-ups to sweep (comma-separated).")
    ap.add_argument("--speedup", type=float, default=None, help="Fly the scenarios at this speed-up (no sweep).")
    ap.add_argument("--scenarios", type=int, default=10, help="How many of the plan's scenarios to fly.")
    ap.add_argument("--sweep-s", type=float, default=600.0, help="Vehicle seconds of each sweep flight.")
    ap.add_argument("--work", type=Path, default=None, help="Directory for the logs and rows (kept; resumable).")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="A short sweep and two cut flights, no calibration.")
    args = ap.parse_args(argv)
    if sitl_binary() is None:
        print(
            f"error: {ENV} is not set; point it at the ArduSub SITL binary (../shared/ardusub/ardusub)", file=sys.stderr
        )
        return 2
    try:
        speedups = [float(s) for s in args.speedups.split(",") if s.strip()]
    except ValueError:
        print(f"error: --speedups: expected numbers like 10,20,40, got {args.speedups!r}", file=sys.stderr)
        return 2
    work = args.work or Path(tempfile.mkdtemp(prefix="rapt_ardusub_"))
    work.mkdir(parents=True, exist_ok=True)
    ids = [s["id"] for s in load_plan(PLAN).scenarios][: 2 if args.quick else args.scenarios]
    if args.quick:
        speedups, args.sweep_s = [s for s in speedups if s <= 20][-1:] or speedups[:1], 300.0
    started = time.perf_counter()
    sweep_rows: list[dict] = []
    speedup = args.speedup
    if speedup is None:
        sweep_rows = sweep(work, ids[0], speedups, args.sweep_s)
        speedup = highest_kept_up(sweep_rows)
        if speedup is None:
            print(f"error: our side fell behind the firmware at speed-up {min(speedups):g}; try lower --speedups",
                  file=sys.stderr)  # fmt: skip
            print(report(sweep_rows, None, [], None))
            return 1
    cut = 600.0 if args.quick else None
    rows = []
    for sid in ids:
        rows.append(
            _cached(
                work, f"{sid}_x{speedup:g}", lambda sid=sid: fly(sid, speedup, work / f"{sid}_x{speedup:g}.mcap", cut)
            )
        )
        print(f"  {sid} x{speedup:g}: {rows[-1].get('ended') or rows[-1].get('error')}", file=sys.stderr, flush=True)
    packs = []
    if not args.quick:  # the first scenario again on the firmware's default pack and on a BlueROV2's
        for ah in (0.0, BLUEROV2_PACK_AH):
            name = f"{ids[0]}_x{speedup:g}_pack{ah:g}"
            packs.append(
                _cached(work, name, lambda ah=ah, name=name: fly(ids[0], speedup, work / f"{name}.mcap", None, ah))
            )
            print(f"  {ids[0]} pack {ah:g} Ah: {packs[-1].get('ended') or packs[-1].get('error')}", file=sys.stderr)
    observe(rows + packs)
    cal = None if args.quick else calibration(rows, work, args.seed)
    print(f"# ArduSub SITL flying field_plans/range2017 ({len(ids)} scenarios; {time.perf_counter() - started:.0f} s; "
          f"work in {work})\n")  # fmt: skip
    print(report(sweep_rows, speedup, rows, cal, packs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
