"""``rapt-plan generate`` end to end: the time per stage of a 100,000-run field plan (issue 6).

Runs the same code as the command (:func:`planner.generate.generate`, progress tracking
included) on the 2017 range mission with the default plan settings — 5 pairs, 2,000
stochastic dithers per pair, robust variants — and prints, per stage, the wall time and
its share, next to the target of 10 minutes for the whole plan.  The study store is a
fresh SQLite file, as on a first run.

Run:  python benchmarks/generate.py [--budget 100000] [--batch-size N] [--executor local|processes] [--quick]

``--quick`` prints the same table for a 5,000-run plan with 200 dithers per pair (about a
minute on 2 cores); the 10-minute target is for the full 100,000 runs and is not judged.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import sim.uuv
from planner.generate import GenerateConfig, auto_batch_size, generate, make_executor

MISSION = Path(__file__).resolve().parents[1] / "examples" / "range2017.toml"
TARGET_S = 600.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
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


if __name__ == "__main__":
    main()
