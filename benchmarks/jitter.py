"""Logs from a vehicle whose reports jitter: the same estimates as from a lock-step-like one (issue 38, item 4).

    python benchmarks/jitter.py [--scenarios pair1a,pair2a] [--speedup 25] [--wall 45]
                                [--jitter 0.25] [--drop 0.1] [--seed 1] [--bootstrap 0] [--quick]

Each scenario of ``field_plans/range2017/`` is flown on the bare front-seat
(``rapt-plan frontseat PLAN --scenario ID --bare``, a process of its own, as a vehicle is another
computer) with an injected execution bias (``--inject-bias speed=1.15,current_offset=0.3``),
through ``--mavlink`` as on a range day (:func:`planner.fly.vehicle.run.run_vehicle`, loopback
MAVLink and a Zenoh session), for ``--wall`` wall seconds at ``--speedup``, under each condition:

* ``exact``: reports on ArduSub's cadence (today's bare front-seat);
* ``exact again``: the same flights again, for how much two jitter-free flights differ on a
  wall-clock-driven vehicle (set-point latency on a loaded machine);
* ``jitter``: every position and attitude report moved by a seeded uniform draw in
  ±``--jitter`` s (``--jitter``);
* ``jitter + drops``: the same, and a share ``--drop`` of those reports never sent.

Per condition the logs are read (:func:`planner.review.logs.read_run`) and fitted jointly by the
functions ``rapt-plan compare`` and ``rapt-plan calibrate`` use: the execution bias
(:func:`planner.review.biasfit.fit_bias`) and the vehicle block
(:func:`planner.review.calibrate.fit_vehicle`).  Printed: the steps logged and replayed, the
step lengths, then per estimate each condition's value and standard error and its difference
from ``exact`` in units of ``exact``'s standard error (the target: within 1); the standard
errors are the fits' analytic (cluster-robust) ones unless ``--bootstrap N`` asks for refits.
``--quick``: the two scenarios for 30 s each.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
BIAS = "speed=1.15,current_offset=0.3"

from planner.fly.flight import flight_from_plan  # noqa: E402
from planner.fly.run_bus import free_port  # noqa: E402
from planner.fly.vehicle.run import run_vehicle  # noqa: E402
from planner.review.biasfit import fit_bias  # noqa: E402
from planner.review.logs import read_run  # noqa: E402
from planner.review.segments import MAX_SETPOINT_DELAY_S, segment_batch, step_lengths  # noqa: E402
from planner.review.vehicle_fit import fit_vehicle  # noqa: E402
from sim.uuv.bias import BIAS_NAMES  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402


def fly(sid: str, log: Path, speedup: float, wall: float, jitter: float, drop: float, seed: int) -> str:
    """One flight of plan scenario ``sid`` on the bare front-seat (its own process); how it ended."""
    port = free_port()
    vehicle = subprocess.Popen(
        [sys.executable, "-m", "planner.cli", "frontseat", str(PLAN), "--scenario", sid]
        + ["--mavlink", f"udpin:127.0.0.1:{port}", "--bare", "--speedup", str(speedup), "--inject-bias", BIAS]
        + ["--jitter", str(jitter), "--drop-reports", str(drop), "--seed", str(seed)],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        result = run_vehicle(
            flight_from_plan(PLAN, sid), f"udpout:127.0.0.1:{port}", log_path=log, timeout_s=wall, guard=None
        )
    finally:
        vehicle.send_signal(signal.SIGINT)
        vehicle.wait(timeout=30)
    return result.ended


def estimates(logs: list[Path], bootstrap: int) -> dict:
    """The bias and vehicle fits of one condition's logs, with what the replay kept of them."""
    runs = [read_run(p) for p in logs]
    mission = flight_from_plan(PLAN, str(runs[0].meta["scenario_id"])).mission
    U = np.array([r.meta["u"] for r in runs])
    starts = list(make_scenarios(mission, U).start_time)
    seg = segment_batch(mission, runs, starts)
    lengths = np.concatenate([step_lengths(r.steps[:, 0], mission.dt)[0] for r in runs])
    late = sum(int(np.sum(r.setpoint_delay_s[:-1] > MAX_SETPOINT_DELAY_S)) for r in runs)
    bias = fit_bias(mission, runs, starts, bootstrap=bootstrap)
    cal = fit_vehicle(mission, runs, starts, bootstrap=bootstrap)
    out = {
        "steps": sum(r.steps.shape[0] - 1 for r in runs),
        "replayed": int(seg.valid.sum()),
        "late": late,
        "length": (float(lengths.min()), float(lengths.max())),
        "est": {},
    }
    for n in BIAS_NAMES:
        out["est"][f"bias {n}"] = (float(getattr(bias.bias, n)), float(bias.stderr[n]), bias.identified[n])
    se_fit = cal.estimate.stderr
    for n in cal.fitted:
        value = cal.value(n)
        out["est"][f"vehicle {n}"] = (value, float(cal.stderr[n]), cal.estimate.identified[n], float(se_fit[n]))
    return out


def report(results: dict) -> None:
    print("\n| condition | steps logged | replayed | late set-points | step length (s) |")
    print("|---|---:|---:|---:|---|")
    for label, r in results.items():
        lo, hi = r["length"]
        print(f"| {label} | {r['steps']} | {r['replayed']} | {r['late']} | {lo:.2f} – {hi:.2f} |")
    base = results["exact"]["est"]
    labels = [c for c in results if c != "exact"]
    print("\n| estimate | exact (s.e.) | " + " | ".join(f"{c}: value, Δ/s.e." for c in labels) + " |")
    print("|---|---:|" + "---:|" * len(labels))
    worst: dict[str, float] = {}
    for name, (v0, se0, ok0, *fit0) in base.items():
        if not ok0:
            continue
        cells = []
        for c in labels:
            v, _, ok, *_ = results[c]["est"][name]
            z = abs(v - v0) / se0 if se0 > 0 else float("inf")
            worst[c] = max(worst.get(c, 0.0), z)
            zf = f" ({abs(v - v0) / fit0[0]:.2f} of the fit's own s.e.)" if fit0 and fit0[0] > 0 else ""
            cells.append(f"{v:.5g}, {z:.2f}{zf}" + ("" if ok else " (not identified)"))
        print(f"| {name} | {v0:.5g} ({se0:.2g}) | " + " | ".join(cells) + " |")
    print("\nlargest |Δ| / s.e. per condition: " + ", ".join(f"{c} {z:.2f}" for c, z in worst.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", default="pair1a,pair2a")
    ap.add_argument("--speedup", type=float, default=25.0)
    ap.add_argument("--wall", type=float, default=45.0, help="wall seconds each flight lasts")
    ap.add_argument("--jitter", type=float, default=0.25)
    ap.add_argument("--drop", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bootstrap", type=int, default=0, help="bootstrap refits behind the s.e. (0: analytic)")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    scenarios = a.scenarios.split(",")
    wall = 30.0 if a.quick else a.wall
    conditions = {"exact": (0.0, 0.0), "exact again": (0.0, 0.0), "jitter": (a.jitter, 0.0)}
    conditions["jitter + drops"] = (a.jitter, a.drop)
    print(f"bias {BIAS}; {len(scenarios)} scenarios x {wall:g} s wall at speed-up {a.speedup:g}")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, (jitter, drop) in conditions.items():
            logs = []
            for sid in scenarios:
                log = Path(tmp) / f"{label.replace(' ', '_')}_{sid}.mcap"
                t0 = time.perf_counter()
                ended = fly(sid, log, a.speedup, wall, jitter, drop, a.seed)
                print(f"{label:>15} {sid}: {ended} ({time.perf_counter() - t0:.0f} s)", flush=True)
                logs.append(log)
            results[label] = estimates(logs, a.bootstrap)
    report(results)


if __name__ == "__main__":
    main()
