"""``rapt-plan generate`` end to end: sharp pairs and robust sides per mission, and time per stage.

Default: the README main job's settings (``--budget 20000 --refine``, 5 pairs, 2,000
dithers per pair, seed 0) on each bundled mission (range2017, uuv18, imitation7). Each runs
twice, side by side: on this checkout, and on a baseline revision checked out into a
temporary git worktree (bisection refinement, unit-cube dithering). The table gives per
mission the pair distances, the share of sides whose dithers show their prediction at
P >= 0.8 (variants included), the runs spent on refinement, dithering and variants, and
the seconds per stage.

Run:  python benchmarks/generate.py [--budget 20000] [--baseline REV] [--missions ...] [--quick]
      python benchmarks/generate.py --straddle [--seeds 0,3] [--baseline REV]  (issue 48: P(straddle) as flown)
      python benchmarks/generate.py --stages [--budget 100000] [--executor ...]  (issue 6's stage table)

``--quick`` runs range2017 alone with 5,000 runs and 200 dithers per pair (under 2 minutes).
``--stages`` times one 100,000-run plan stage by stage, against the 10-minute target.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import sim.uuv
from planner.plan.generate import GenerateConfig, auto_batch_size, generate, make_executor

MISSION = Path(__file__).resolve().parents[1] / "examples" / "range2017.toml"
TARGET_S = 600.0


def stages() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stages", action="store_true")
    ap.add_argument("--budget", type=int, default=None, help="search runs (default 100000; --quick: 5000)")
    ap.add_argument("--batch-size", type=int, default=None, help="default: as rapt-plan generate chooses")
    ap.add_argument("--dithers", type=int, default=None, help="dithers per pair (default 2000; --quick: 200)")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--executor", default="local")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="a 5,000-run plan, 200 dithers per pair (about a minute)")
    args = ap.parse_args()
    if args.budget is None:
        args.budget = 5_000 if args.quick else 100_000
    if args.dithers is None:
        args.dithers = 200 if args.quick else 2000

    mission = sim.uuv.load_mission(MISSION)
    batch = args.batch_size or auto_batch_size(args.budget)
    executor, close = make_executor(args.executor)
    timings: dict[str, float] = {}
    last = {"search": (0, 0.0)}
    started = time.perf_counter()

    def progress(stage: str, done: int, total: int, detail: str) -> None:
        if stage == "search":
            last["search"] = (done, detail)

    with tempfile.TemporaryDirectory() as tmp:
        cfg = GenerateConfig(
            budget=args.budget,
            batch_size=batch,
            dithers=args.dithers,
            pairs=args.pairs,
            seed=args.seed,
            executor=executor,
            store=Path(tmp) / "study.db",
        )
        try:
            plan = generate(mission, MISSION, Path(tmp) / "plan", cfg, progress, timings)
        finally:
            close()
    total = time.perf_counter() - started

    print(
        f"rapt-plan generate {MISSION.name} --budget {args.budget:,} (batches of {batch:,}, "
        f"{args.dithers:,} dithers per pair, executor {args.executor}, {os.cpu_count()} cores)"
    )
    print(f"{'stage':>12} {'seconds':>8} {'share':>6}")
    for stage, seconds in timings.items():
        print(f"{stage:>12} {seconds:>8.1f} {seconds / total:>6.0%}")
    if args.quick:
        verdict = "not judged (--quick; the target is for --budget 100000)"
    else:
        verdict = f"{'met' if total <= TARGET_S else 'NOT met'} ({total / TARGET_S:.2f} of the target)"
    print(f"{'total':>12} {total:>8.1f} {'':>6}  target <= {TARGET_S:.0f} s: {verdict}")
    study = plan["study"]
    print(
        f"search: {args.budget / timings['search']:,.0f} runs/s; {study['valid_runs']:,} valid, "
        f"{study['invalid_runs']:,} invalid; at the end: {last['search'][1]}"
    )
    print(
        f"plan: {len(plan['pairs'])} pairs, {len(plan['variants'])} robust variants; pair distances "
        + ", ".join(f"{p['distance']:.3f}" for p in plan["pairs"])
    )
    for s in plan["scenarios"]:
        d = s["dithering"]
        print(
            f"  {s['id']:>7} {s['predicted']['mode']} P(predicted mode) = {d.get('p_predicted_mode', float('nan')):.2f}"
        )


# -- issue 24: sharp pairs and robust sides, against a baseline revision ----------------------
MISSIONS = ("range2017", "uuv18", "imitation7")
BASELINE_REV = "4f1aaac"  # main before the focused refinement and the noise-based dithering
ROOT = Path(__file__).resolve().parents[1]

#: Runs in a subprocess on either revision's code; prints one JSON line of figures.
DRIVER = r"""
import json, sys, time
from pathlib import Path
import sim.uuv
from planner.plan.generate import GenerateConfig, generate
mission_file, out, budget, dithers, refine = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
mission = sim.uuv.load_mission(mission_file)
timings = {}
cfg = GenerateConfig(budget=budget, dithers=dithers, pairs=5, seed=0, refine=refine, store=out / "study.db")
t0 = time.perf_counter()
plan = generate(mission, Path(mission_file), out / "plan", cfg, None, timings)
total = time.perf_counter() - t0
held, sides = 0, 0
variants = {v["variant_of"]: v for v in plan["variants"]}
for s in plan["scenarios"]:
    d = s["dithering"]
    p = d.get("p_predicted", d.get("p_predicted_mode"))
    v = variants.get(s["id"])
    pv = None if v is None else v.get("p_predicted", v.get("p_predicted_mode"))
    sides += 1
    held += (p is not None and p >= 0.8) or (pv is not None and pv >= 0.8)
runs = plan["study"].get("runs", {})
print(json.dumps({
    "distances": [p["distance"] for p in plan["pairs"]],
    "verdicts": [p.get("verdict", "-") for p in plan["pairs"]],
    "held": held, "sides": sides,
    "refinement_runs": runs.get("refinement"), "dithering_runs": runs.get("dithering", len(plan["scenarios"]) * (dithers // 2)),
    "variant_runs": runs.get("variants"), "timings": timings, "total": total,
}))
"""


def _run(code_root: Path, mission: str, tmp: Path, budget: int, dithers: int, refine: int) -> dict:
    out = tmp / f"{code_root.name}-{mission}"
    out.mkdir(parents=True)
    env = {**os.environ, "PYTHONPATH": str(code_root)}
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            DRIVER,
            str(ROOT / "examples" / f"{mission}.toml"),
            str(out),
            str(budget),
            str(dithers),
            str(refine),
        ],
        env=env,
        cwd=code_root,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare() -> None:
    ap = argparse.ArgumentParser(
        description="Sharp pairs and robust sides per bundled mission, against a baseline revision"
    )
    ap.add_argument("--budget", type=int, default=20_000, help="the README main job's budget")
    ap.add_argument("--dithers", type=int, default=2000)
    ap.add_argument("--baseline", default=BASELINE_REV, help="git revision of the code to compare against")
    ap.add_argument("--missions", nargs="*", default=list(MISSIONS))
    ap.add_argument("--quick", action="store_true", help="range2017 only, 5,000 runs, 200 dithers per pair")
    args = ap.parse_args()
    if args.quick:
        args.budget, args.dithers, args.missions = 5_000, 200, ["range2017"]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        base_root = tmp / "baseline"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base_root), args.baseline],
            check=True,
            capture_output=True,
        )
        try:
            rows = []
            for mission in args.missions:
                before = _run(base_root, mission, tmp, args.budget, args.dithers, 12)  # the old --refine default
                after = _run(ROOT, mission, tmp, args.budget, args.dithers, 160)  # the new one
                rows.append((mission, before, after))
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_root)], check=False)
    print(
        f"rapt-plan generate MISSION --budget {args.budget:,} --refine, {args.dithers:,} dithers per pair, seed 0, "
        f"{os.cpu_count()} cores; baseline {args.baseline} (bisection, unit-cube sigma 0.02, P of the mode)"
    )
    print(
        f"{'mission':<11} {'code':<9} {'pair distances':<36} {'max':>6} {'sides P>=0.8':>12} "
        f"{'refine runs':>11} {'dither runs':>11} {'variant runs':>12} {'total s':>8}"
    )
    for mission, before, after in rows:
        for name, r in (("baseline", before), ("now", after)):
            d = r["distances"]
            print(
                f"{mission:<11} {name:<9} {', '.join(f'{x:.3f}' for x in d):<36} {max(d, default=0):>6.3f} "
                f"{r['held']:>5}/{r['sides']:<6} {str(r['refinement_runs'] or '-'):>11} {r['dithering_runs']:>11,} "
                f"{str(r['variant_runs'] if r['variant_runs'] is not None else '-'):>12} {r['total']:>8.1f}"
            )
        print(
            f"{'':<11} {'verdicts':<9} {', '.join(after['verdicts'])}; max distance ratio now/baseline "
            f"{max(after['distances']) / max(before['distances']):.2f}"
        )
    print("seconds per stage (baseline -> now):")
    for mission, before, after in rows:
        stages = dict.fromkeys(list(before["timings"]) + list(after["timings"]))
        print(
            f"  {mission}: "
            + ", ".join(f"{s} {before['timings'].get(s, 0):.0f} -> {after['timings'].get(s, 0):.0f}" for s in stages)
        )


# -- issue 48: pairs chosen by the chance they show, against the revision before ---------------
STRADDLE_BASELINE = "c694fb9"  # main before pairs were chosen by P(straddle)

#: Per pair, P(straddle) of the sides a range flies (the variant where the plan names one), on either revision.
STRADDLE_DRIVER = r"""
import json, sys, time
from pathlib import Path
import numpy as np
import sim.uuv
from planner.plan.generate import GenerateConfig, generate
mission_file, out, budget, seed = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
mission = sim.uuv.load_mission(mission_file)
cfg = GenerateConfig(budget=budget, pairs=5, seed=seed, refine=160, store=out / "study.db")
t0 = time.perf_counter()
plan = generate(mission, Path(mission_file), out / "plan", cfg)
total = time.perf_counter() - t0
rows = {s["id"]: s for s in plan["scenarios"] + plan["variants"]}
pairs = []
for pr in plan["pairs"]:
    flown = [v or s for s, v in zip(pr["scenarios"], pr.get("variants") or [None, None])]
    p = [rows[f].get("p_predicted", rows[f].get("dithering", {}).get("p_predicted")) for f in flown]
    u = [np.array(rows[f]["u"]) for f in flown]
    pairs.append({"elements": pr["elements"], "modes": pr["modes"], "p_sides": p,
                  "p_straddle": None if None in p else p[0] * p[1], "flown_distance": float(np.linalg.norm(u[0] - u[1]))})
print(json.dumps({"pairs": pairs, "total": total, "unreached": plan["study"].get("unreached")}))
"""


def _straddle_run(code_root: Path, tmp: Path, budget: int, seed: int) -> dict:
    out = tmp / f"{code_root.name}-seed{seed}"
    out.mkdir(parents=True)
    args = [sys.executable, "-c", STRADDLE_DRIVER, str(MISSION), str(out), str(budget), str(seed)]
    env = {**os.environ, "PYTHONPATH": str(code_root)}
    done = subprocess.run(args, env=env, cwd=code_root, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def straddle() -> None:
    """range2017 at the README's settings, per seed, before and now: P(straddle) of each pair as flown."""
    ap = argparse.ArgumentParser(description="Pairs chosen by the chance they show, against the revision before")
    ap.add_argument("--straddle", action="store_true")
    ap.add_argument("--budget", type=int, default=20_000)
    ap.add_argument("--seeds", default="0,3")
    ap.add_argument("--baseline", default=STRADDLE_BASELINE)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        base_root = tmp / "baseline"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base_root), args.baseline],
                       check=True, capture_output=True)  # fmt: skip
        try:
            rows = [(seed, _straddle_run(base_root, tmp, args.budget, seed), _straddle_run(ROOT, tmp, args.budget, seed))
                    for seed in seeds]  # fmt: skip
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_root)], check=False)
    print(f"rapt-plan generate range2017.toml --budget {args.budget:,} --refine --seed S; baseline {args.baseline}")
    print("| seed | code | P(straddle) per pair, as flown | pairs >= 0.8 | sides >= 0.8 | flown sides apart, max | s |")
    print("|---:|---|---|---:|---:|---:|---:|")
    for seed, *codes in rows:
        for name, r in zip(("baseline", "now"), codes):
            ps = [p["p_straddle"] for p in r["pairs"]]
            sides = sum(1 for p in r["pairs"] for v in p["p_sides"] if v is not None and v >= 0.8)
            print(f"| {seed} | {name} | {', '.join('-' if v is None else f'{v:.2f}' for v in ps)} "
                  f"| {sum(1 for v in ps if v is not None and v >= 0.8)} / {len(ps)} | {sides} / {2 * len(ps)} "
                  f"| {max(p['flown_distance'] for p in r['pairs']):.3f} | {r['total']:.0f} |")  # fmt: skip


if __name__ == "__main__":
    if "--stages" in sys.argv:
        stages()
    elif "--straddle" in sys.argv:
        straddle()
    else:
        compare()
