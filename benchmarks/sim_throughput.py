"""Simulator throughput and the 2017 mission's performance modes (issues 4 and 51).

Tables measured side by side in one run, for each mission (default ``range2017`` and
``uuv18``, the 18-parameter mission of section 3.7):

1. Full simulations per second against batch size (deterministic; one stochastic row),
   counting only valid scenarios — invalid ones are reported, not simulated — in one
   process and split over ``--workers`` processes as a study's ``processes`` executor
   splits a batch; the split's scores must equal the single process's to the last bit.
2. The same code one scenario at a time (a per-scenario Python loop, as a simulator that
   cannot batch would run it) and the batch's speed-up over it.
3. A Sobol study of the mission: how the valid runs split over the performance
   modes TF/SS/MS/TS and how the boundary pairs split over boundary types (Figure 4.23).

Run:  python benchmarks/sim_throughput.py [--missions range2017 uuv18] [--sizes 256 1024 4096 16384]
      [--workers 2] [--study 4096] [--quick]

``--quick`` prints the same tables from a small run: batches of 256, 1,024 and
4,096 (the stochastic row at 4,096), 5 scenarios one at a time, a 1,024-scenario study.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing
import time
from pathlib import Path

import numpy as np
from scipy.stats import qmc

import rapt
import sim.uuv
from sim.uuv.scoring import MODE_NAMES

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _chunk(mission, X: np.ndarray, seed: int, stochastic: bool) -> np.ndarray:
    return sim.uuv.simulate(mission, X, seed=seed, stochastic=stochastic).scores


def split_simulate(pool: cf.Executor, workers: int, mission, X, seed: int, stochastic: bool) -> np.ndarray:
    """Scores of ``X`` simulated in ``workers`` equal chunks, one per process (rows are independent)."""
    parts = np.array_split(np.arange(X.shape[0]), workers)
    futures = [pool.submit(_chunk, mission, X[rows], seed, stochastic) for rows in parts]
    return np.concatenate([f.result() for f in futures])


def throughput(mission, sizes: list[int], loop_n: int, workers: int) -> float:
    X = qmc.Sobol(mission.dim, seed=0).random(max(sizes))
    print(
        f"1. {mission.name}: full simulations per second (numpy, dt = {mission.dt:g} s, "
        f"time limit {mission.time_limit_s:g} s), 1 process and {workers} processes"
    )
    print(
        f"{'batch':>7} {'mode':>13} {'valid runs':>10} {'1 proc runs/s':>14} {f'{workers} procs runs/s':>15} "
        f"{'ratio':>6} {'same bits':>9} {'10^6 runs (min)':>16}"
    )
    best = 0.0
    with cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver")) as pool:
        split_simulate(pool, workers, mission, X[: 2 * workers], 1, False)  # start the workers
        for n in sizes:
            for stochastic in (False, True) if n == sizes[-1] else (False,):
                t0 = time.perf_counter()
                r = sim.uuv.simulate(mission, X[:n], seed=1, stochastic=stochastic)
                t1 = time.perf_counter()
                split = split_simulate(pool, workers, mission, X[:n], 1, stochastic)
                t2 = time.perf_counter()
                valid = int(r.valid.sum())
                one, many = valid / (t1 - t0), valid / (t2 - t1)
                if not stochastic:
                    best = max(best, one)
                same = np.array_equal(split, r.scores, equal_nan=True)
                print(
                    f"{n:>7,} {'stochastic' if stochastic else 'deterministic':>13} {valid:>10,} {one:>14.0f} "
                    f"{many:>15.0f} {many / one:>5.2f}x {'yes' if same else 'NO':>9} {1e6 / many / 60:>16.1f}"
                )
    rows = np.flatnonzero(sim.uuv.simulate(mission, X[: loop_n * 2]).valid)[:loop_n]
    t0 = time.perf_counter()
    for i in rows:
        sim.uuv.simulate(mission, X[i : i + 1])
    t = time.perf_counter() - t0
    loop_rate = rows.size / t
    print(
        f"\n2. The same code one scenario at a time ({rows.size} scenarios): {loop_rate:.1f} runs/s; "
        f"the best batch is {best / loop_rate:.0f}x faster"
    )
    return best


def modes_and_boundaries(mission, n: int) -> None:
    X = qmc.Sobol(mission.dim, seed=1).random(n)
    r = sim.uuv.simulate(mission, X)
    Xv, modes = X[r.valid], r.modes[r.valid]
    print(
        f"\n3. Sobol study of {n:,} {mission.name} scenarios: {r.valid.sum():,} valid "
        f"({(~r.valid).sum():,} invalid, e.g. {_top_reason(r)})"
    )
    counts = np.bincount(modes, minlength=4)
    print(
        "   performance modes: "
        + ", ".join(f"{MODE_NAMES[k]} {c:,} ({c / counts.sum():.0%})" for k, c in enumerate(counts))
    )
    bp = rapt.boundary_pairs(Xv, labels=modes)
    present = sorted(set(modes.tolist()))
    print(f"   boundary pairs: {len(bp):,} in {len(bp.types())} boundary types")
    for a, b, c in sorted(bp.types(), key=lambda t: -t[2]):
        ma, mb = MODE_NAMES[present[a]], MODE_NAMES[present[b]]
        sel = bp.of_type(a, b)
        print(f"   {ma:>2}/{mb:<2} {c:>6,} pairs  median distance {np.median(sel.distance):.3f}")


def _top_reason(r) -> str:
    reasons = [x for x in r.invalid_reason if x]
    if not reasons:
        return "none"
    values, counts = np.unique(reasons, return_counts=True)
    return f"'{values[np.argmax(counts)]}'"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="+", default=["range2017", "uuv18"], help="example missions (default both)")
    ap.add_argument("--workers", type=int, default=2, help="processes a batch is split over (default 2)")
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=None,
        help="batch sizes (default 256 1024 4096 16384; --quick: 256 1024 4096)",
    )
    ap.add_argument("--loop", type=int, default=None, help="scenarios run one at a time (default 20; --quick: 5)")
    ap.add_argument(
        "--study",
        type=int,
        default=None,
        help="Sobol scenarios for the mode distribution (default 4096; --quick: 1024)",
    )
    ap.add_argument("--quick", action="store_true", help="the same tables from a small run (under a minute)")
    args = ap.parse_args()
    if args.sizes is None:
        args.sizes = [256, 1024, 4096] if args.quick else [256, 1024, 4096, 16384]
    if args.loop is None:
        args.loop = 5 if args.quick else 20
    if args.study is None:
        args.study = 1024 if args.quick else 4096
    for name in args.missions:
        mission = sim.uuv.load_mission(EXAMPLES / f"{name}.toml")
        throughput(mission, sorted(args.sizes), args.loop, args.workers)
        modes_and_boundaries(mission, args.study)
        print()


if __name__ == "__main__":
    main()
