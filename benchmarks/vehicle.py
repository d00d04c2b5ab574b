"""A field plan flown on a vehicle we do not simulate in lock-step (issue 22), measured.

Every scenario of ``field_plans/range2017/`` is flown through ``--mavlink`` exactly as on a
range day (:func:`planner.fly.vehicle.run.run_vehicle`: bring-up, vehicle-paced back-seat,
virtual sonar and fuel gauge, watchdog, referee) against our front-seat as a bare
autopilot (:class:`sim.uuv.ardusub.frontseat.FrontSeat` with ``bare=True``: its own stream rates,
no sonar, an estimator that is not ready at boot, ArduSub's 3 s set-point timeout), in a
process of its own, at each speed-up.  Per scenario and speed-up:

* observed versus predicted mode (the plan's prediction);
* path error: distance between the flown track and the batch simulator's predicted track
  at the same scenario times (mean and max, over the span both cover);
* watchdog interventions (``yes``) and breaches it only recorded (``rec``): by default the
  watchdog records no-go entries without taking control, because range2017's no-go areas
  (the barriers among them) are virtual and the plan predicts some scenarios to cross one —
  cutting those runs short would hide the mission outcome the plan predicts;
* decision latency p50/p99, measured at the vehicle: a position report leaves it stamped
  ``time_boot_ms`` = T, and the set-point of the decision taken on it arrives stamped T;
* missed decisions (periods of the vehicle's clock with no decision) and the share of
  decisions taken on an input older than one decision period.

Targets: the predicted mode on at least 9 of 10 scenarios at speed-up 10, zero missed
decisions, p99 latency under 50 ms.

Run:  python benchmarks/vehicle.py [--speedups 1,10,50] [--scenarios pair1a,pair2b] [--jobs 2] [--quick]

``--quick`` flies two scenarios side by side at speed-up 50 (about a minute).  Speed-up 1 flies each
scenario in real time (up to 45 minutes): give it ``--jobs`` equal to the number of
scenarios to fly them side by side (a real-time vehicle needs little CPU).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import queue
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"


def _vehicle(plan_path: str, sid: str, port: int, speedup: float, stop, results) -> None:
    """The bare-autopilot vehicle in its own process, as a real vehicle is another computer."""
    from planner.common.plans import load_plan
    from sim.uuv.ardusub.frontseat import FrontSeat

    plan = load_plan(plan_path)
    fs = FrontSeat(plan.mission, plan.u(sid), f"udpin:127.0.0.1:{port}", bare=True, speedup=speedup)
    try:
        while not stop.is_set():
            fs.serve(duration_s=0.5)
    finally:
        results.put(("vehicle", dict(fs.stats.latency_s)))
        fs.close()


def _stack(plan_path: str, sid: str, port: int, speedup: float, record: tuple, results) -> None:
    """The whole range-day stack on the vehicle's port, as `rapt-plan run PLAN --scenario ID --mavlink`."""
    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.bringup import BringUpTimeouts
    from planner.fly.vehicle.run import run_vehicle
    from sim.uuv.scoring import mode_name

    flight = flight_from_plan(Path(plan_path), sid)
    limit = flight.mission.time_limit_s / speedup * 1.5 + 120
    with tempfile.TemporaryDirectory() as tmp:
        try:
            r = run_vehicle(
                flight,
                f"udpout:127.0.0.1:{port}",
                log_path=Path(tmp) / "run.mcap",
                timeouts=BringUpTimeouts().scaled(max(1.0, 10 / speedup)),
                timeout_s=limit,
                record_only=record,
                guard=None,  # the simulated front-seat has no scripting
            )
        except Exception as exc:  # a failed bring-up is a result too
            results.put(("stack", {"error": f"{type(exc).__name__}: {exc}"}))
            return
    results.put(
        (
            "stack",
            {
                "mode": mode_name(r.scores),
                "ended": r.ended,
                "watchdog": r.watchdog,
                "violations": sorted(r.violations),
                "track": r.track,
                "decisions": r.decisions,
                "decision_ticks": r.decision_ticks,
                "input_age_ms": r.input_age_ms,
                "wall_s": r.wall_s,
                "sim_s": r.sim_s,
                "bringup_s": next((s.wall_s for s in r.timeline if s.name == "clock"), float("nan")),
            },
        )
    )


def fly(plan_path: str, sid: str, speedup: float, record: tuple = ("nogo",)) -> dict:
    """One scenario at one speed-up: the vehicle and the stack as two processes on loopback."""
    from planner.fly.run_bus import free_port

    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    stop = ctx.Event()
    port = free_port()
    vehicle = ctx.Process(target=_vehicle, args=(plan_path, sid, port, speedup, stop, results))
    stack = ctx.Process(target=_stack, args=(plan_path, sid, port, speedup, record, results))
    vehicle.start()
    stack.start()
    got: dict = {}
    try:
        while "stack" not in got:
            try:
                kind, value = results.get(timeout=1.0)
                got[kind] = value
            except queue.Empty:
                if not stack.is_alive() and "stack" not in got:
                    got["stack"] = {"error": f"the stack process died (exit {stack.exitcode})"}
        stop.set()
        while "vehicle" not in got:
            kind, value = results.get(timeout=30)
            got[kind] = value
    finally:
        stop.set()
        for p in (stack, vehicle):
            p.join(timeout=30)
            if p.is_alive():
                p.terminate()
    out = dict(got["stack"])
    out["latency_ms"] = [got["vehicle"][t] * 1000 for t in out.get("decision_ticks", []) if t in got["vehicle"]]
    return out


def path_error(plan, sid: str, track: np.ndarray) -> tuple[float, float]:
    """Mean and max distance (m) from the flown track to the predicted one at the same scenario times."""
    import sim.uuv

    predicted = sim.uuv.simulate(plan.mission, plan.u(sid)[None, :], trajectories=True).trajectory(0)
    if predicted is None or len(track) == 0:
        return float("nan"), float("nan")
    t = track[:, 0]
    keep = t <= predicted[-1, 0]
    px = np.interp(t[keep], predicted[:, 0], predicted[:, 1])
    py = np.interp(t[keep], predicted[:, 0], predicted[:, 2])
    d = np.hypot(track[keep, 1] - px, track[keep, 2] - py)
    return (float(d.mean()), float(d.max())) if d.size else (float("nan"), float("nan"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speedups", default="1,10,50")
    ap.add_argument("--scenarios", default="all", help="comma-separated scenario ids of the plan, or all")
    ap.add_argument("--jobs", type=int, default=1, help="scenarios flown side by side")
    ap.add_argument(
        "--watchdog-record",
        default="nogo",
        help="watchdog reasons logged without taking control (comma-separated; '' for none)",
    )
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    from concurrent.futures import ThreadPoolExecutor

    from planner.common.plans import load_plan

    plan = load_plan(PLAN)
    ids = [s["id"] for s in plan.scenarios] + [v["id"] for v in plan.variants]
    speedups = [float(s) for s in args.speedups.split(",")]
    if args.quick:
        ids, speedups, args.jobs = ["pair1a", "pair2b"], [50.0], 2
    elif args.scenarios != "all":
        ids = args.scenarios.split(",")
    record = tuple(r for r in args.watchdog_record.split(",") if r)
    predicted = {sid: str(plan.scenario(sid)["predicted"]["mode"]) for sid in ids}
    print(f"{plan.mission.name}: {len(ids)} scenarios of {PLAN.relative_to(ROOT)} on the bare-autopilot front-seat")
    print(f"watchdog: takes control on every rule but {', '.join(record) or 'none'} (recorded: 'rec' in column wd)")
    summary = []
    for speedup in speedups:
        started = time.perf_counter()
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = dict(zip(ids, pool.map(lambda sid, s=speedup: fly(str(PLAN), sid, s, record), ids)))
        print(f"\nspeed-up {speedup:g} ({time.perf_counter() - started:,.0f} s wall)")
        head = f"{'scenario':>8} {'pred':>4} {'obs':>4} {'ended':>26} {'path m mean/max':>16} {'wd':>3}"
        print(head + f" {'dec':>5} {'miss':>4} {'old%':>5} {'p50 ms':>7} {'p99 ms':>7} {'bring-up s':>10}")
        matched = missed = old = n_dec = 0
        lat_all: list[float] = []
        for sid in ids:
            r = runs[sid]
            if "error" in r:
                print(f"{sid:>8} {predicted[sid]:>4}  error: {r['error']}")
                continue
            mean, worst = path_error(plan, sid, r["track"])
            d = r["decisions"]
            ages = np.asarray(r["input_age_ms"], dtype=float)
            share_old = float((ages > plan.mission.dt * 1000).mean() * 100) if ages.size else float("nan")
            lat = np.asarray(r["latency_ms"])
            lat_all += lat.tolist()
            matched += r["mode"] == predicted[sid]
            missed += d["missed"]
            old += int((ages > plan.mission.dt * 1000).sum())
            n_dec += d["decisions"]
            p50, p99 = (np.percentile(lat, 50), np.percentile(lat, 99)) if lat.size else (np.nan, np.nan)
            print(
                f"{sid:>8} {predicted[sid]:>4} {r['mode']:>4} {r['ended'][:26]:>26} {mean:>7.1f}/{worst:>8.1f}"
                f" {'yes' if r['watchdog'] else ('rec' if r['violations'] else '-'):>3} {d['decisions']:>5} {d['missed']:>4} {share_old:>5.1f}"
                f" {p50:>7.1f} {p99:>7.1f} {r['bringup_s']:>10.1f}"
            )
        lat_all_a = np.asarray(lat_all)
        p99_all = float(np.percentile(lat_all_a, 99)) if lat_all_a.size else float("nan")
        summary.append((speedup, matched, len(ids), missed, p99_all, old, n_dec))
    print("\nsummary (targets at speed-up 10: predicted mode >= 9 of 10, zero missed decisions, p99 < 50 ms)")
    print(
        f"{'speed-up':>8} {'modes as predicted':>19} {'missed':>7} {'p99 latency ms':>15} {'decisions on old input':>23}"
    )
    for speedup, matched, n, missed, p99, old, n_dec in summary:
        print(f"{speedup:>8g} {f'{matched} of {n}':>19} {missed:>7} {p99:>15.1f} {f'{old} of {n_dec}':>23}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MAVLINK20", "1")
    raise SystemExit(main())
