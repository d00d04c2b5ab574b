"""``rapt-plan generate --noisy-search`` against the deterministic search: do its pairs hold under dithering?

Section 4.2.3 concludes that on a noisy system the search should run on the stochastic
simulator and be steered by continuous metrics, as binary scores blur into fuzzy regions.
This plans the same mission with the same budget, dithers and seed twice, once per search,
and counts per plan the pairs that hold when dithered by the expected execution noise:
verdict *sharp* or *robust* (both flown sides at P >= 0.9, variants included), and
P(straddle) >= 0.8. Target: the noisy search's pairs hold at least as often.

Run:  python benchmarks/noisy_search.py [--missions range2017,uuv18] [--seeds 0,1,2]
                                        [--budget 5000] [--dithers 400] [--pairs 5]
``--quick``: range2017, seed 0, 2,000 runs, 200 dithers per pair, 3 pairs (a few minutes).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import sim.uuv
from planner.plan.generate import GenerateConfig, generate

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SEARCHES = {"deterministic": False, "noisy": True}


def plan_once(mission_name: str, seed: int, noisy: bool, args: argparse.Namespace) -> dict:
    """One plan in a temporary directory: its pairs' verdicts, P(straddle), distances and seconds."""
    path = EXAMPLES / f"{mission_name}.toml"
    mission = sim.uuv.load_mission(path)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = GenerateConfig(
            budget=args.budget,
            pairs=args.pairs,
            seed=seed,
            dithers=args.dithers,
            store=Path(tmp) / "study.db",
            noisy_search=noisy,
        )
        timings: dict[str, float] = {}
        start = time.perf_counter()
        plan = generate(mission, path, Path(tmp) / "out", cfg, timings=timings)
        seconds = time.perf_counter() - start
    pairs = plan["pairs"]
    straddle = [float(p.get("p_straddle") or 0.0) for p in pairs]
    return {
        "holds": sum(p.get("verdict") in ("sharp", "robust") for p in pairs),
        "straddle_08": sum(s >= 0.8 for s in straddle),
        "n": len(pairs),
        "straddle": straddle,
        "distance": [float(p["distance"]) for p in pairs],
        "verdicts": [p.get("verdict", "-") for p in pairs],
        "seconds": seconds,
        "search_s": timings.get("search", 0.0),
    }


def row(mission: str, seed: int, search: str, r: dict) -> str:
    straddle = ", ".join(f"{s:.2f}" for s in r["straddle"])
    return (
        f"| {mission} | {seed} | {search} | {r['holds']} / {r['n']} | {r['straddle_08']} / {r['n']} | "
        f"{straddle} | {np.mean(r['straddle']):.2f} | {np.median(r['distance']):.3f} | "
        f"{r['search_s']:.0f} / {r['seconds']:.0f} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", default="range2017")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--budget", type=int, default=5000)
    ap.add_argument("--dithers", type=int, default=400)
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="range2017, seed 0, 2,000 runs, 200 dithers, 3 pairs")
    args = ap.parse_args()
    if args.quick:
        args.missions, args.seeds, args.budget, args.dithers, args.pairs = "range2017", "0", 2000, 200, 3
    print(f"budget {args.budget}, {args.dithers} dithers per pair, {args.pairs} pairs")
    print(
        "| mission | seed | search | pairs that hold (sharp/robust) | P(straddle) >= 0.8 | P(straddle) per pair "
        "| mean | median distance | search / total s |"
    )
    print("|---|---:|---|---:|---:|---|---:|---:|---:|")
    totals = {s: np.zeros(3) for s in SEARCHES}
    for mission in args.missions.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            for search, noisy in SEARCHES.items():
                r = plan_once(mission, seed, noisy, args)
                totals[search] += (r["holds"], r["straddle_08"], r["n"])
                print(row(mission, seed, search, r), flush=True)
    for search, (holds, s08, n) in totals.items():
        print(f"{search}: {holds:.0f} / {n:.0f} pairs hold, {s08:.0f} / {n:.0f} at P(straddle) >= 0.8")
    met = totals["noisy"][0] / max(totals["noisy"][2], 1) >= totals["deterministic"][0] / max(
        totals["deterministic"][2], 1
    )
    print(f"target (noisy pairs hold at least as often): {'met' if met else 'NOT met'}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
