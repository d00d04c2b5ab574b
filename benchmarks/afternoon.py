"""The afternoon conducted run by run against fixed afternoons, on a simulated range day (issue 49).

    python benchmarks/afternoon.py [--days 12] [--budgets 10,14,20] [--noise 1.5] [--bias speed=0.95,...]
                                   [--work DIR] [--quick]

The vehicle is the batch simulator flown as the water flies it, not as the plan predicts: every
run is one stochastic run (the simulator's in-run effects on) of the scenario moved by Gaussian
execution noise ``--noise`` times the plan's (``study.dithering.sigma_u``), under an execution bias
the plan does not know (``--bias``).  So a side shows its outcome with its own per-run chance q,
which the table prints (1 - q is its flip probability, measured on 400 such runs).

The plan is range2017's, generated as ``rapt-plan generate examples/range2017.toml --budget 4000
--pairs 5`` does (``--quick``: 1,500 runs, 100 dithers per side), into ``--work`` and kept: its
study store is where ``next`` finds new pairs for a boundary that fell through.  Each simulated day flies, with the same vehicle and seeds:

* ``each side once``: every pair side as the range flies it (its robust variant where the plan made
  one), 10 runs;
* ``each side twice``: the same list twice, 20 runs;
* ``next``, with a budget of ``--budgets`` runs: ``rapt-plan next``'s decision
  (:func:`planner.conduct.next_run.decide`) after every run, on its own copy of the plan (its moves are
  written there), until it stops or the budget is spent.  No logs are read: the afternoon's bias is
  not refitted, the noise's scale is, from the outcomes.

Boundaries are confirmed by the rule both ``compare`` and ``next`` use
(:mod:`planner.review.confirmations`).  Printed per policy: runs spent, boundaries confirmed, and
boundaries confirmed per run, as means over the days, with the ratio to "each side twice".
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import sim.uuv  # noqa: E402
from planner.common.plans import Plan, load_plan  # noqa: E402
from planner.conduct.day_record import DayRecord  # noqa: E402
from planner.conduct.new_pairs import study_alternatives  # noqa: E402
from planner.conduct.next_run import afternoon, decide  # noqa: E402
from planner.review.confirmations import (  # noqa: E402
    RunOutcome,
    boundaries_confirmed,
    confirmation_table,
    outcome_columns,
)
from planner.review.forecast import plan_noise  # noqa: E402
from sim.uuv.bias import Bias, parse_bias  # noqa: E402

MISSION = ROOT / "examples" / "range2017.toml"
#: The plan's search budget (``--quick``: the smaller, with fewer dithers per side) and pairs.
BUDGET, QUICK_BUDGET, QUICK_DITHERS, PAIRS = 4000, 1500, 100, 5


def make_plan(work: Path, budget: int) -> Path:
    """range2017's plan in ``work/plan<budget>`` with its study store, as ``rapt-plan generate`` writes it (made
    once per work directory)."""
    from planner.plan.generate import GenerateConfig, generate

    out = work / f"plan{budget}"
    if not (out / "plan.json").is_file():
        out.mkdir(parents=True, exist_ok=True)
        dithers = {} if budget != QUICK_BUDGET else {"dithers": QUICK_DITHERS}
        cfg = GenerateConfig(budget=budget, pairs=PAIRS, seed=0, store=out / "study.db", **dithers)
        generate(sim.uuv.load_mission(MISSION), MISSION, out, cfg)
    return out / "plan.json"


class Vehicle:
    """The simulated day's vehicle: a scenario flown with execution noise, stochastic, under a bias."""

    def __init__(self, plan: Plan, noise: float, bias: Bias):
        self.mission = plan.mission
        self.sigma = plan_noise(plan) * noise
        self.bias = bias

    def fly(self, u: np.ndarray, rng: np.random.Generator, n: int = 1) -> np.ndarray:
        """``n`` runs' scores."""
        U = np.clip(u[None, :] + self.sigma * rng.standard_normal((n, u.size)), 0.0, 1.0)
        r = sim.uuv.simulate(self.mission, U, seed=int(rng.integers(2**31)), stochastic=True, bias=self.bias)
        return np.where(r.valid[:, None], r.scores, np.nan)


def flown_list(plan: Plan) -> list[str]:
    """Every pair side as the range flies it: its robust variant where the plan made one."""
    variant = {v["variant_of"]: v["id"] for v in plan.variants}
    return [variant.get(s, s) for pair in plan.pairs for s in pair["scenarios"]]


def confirmed(plan: Plan, runs: list[RunOutcome]) -> int:
    """Boundaries confirmed by ``runs`` (by a pair of the plan, or a new pair next wrote across the boundary)."""
    day = afternoon(plan, [])
    return boundaries_confirmed(plan, confirmation_table(plan, day.names, day.predicted, runs))


def outcome(scores: np.ndarray) -> np.ndarray | None:
    return None if np.isnan(scores[0]) else scores


def fixed_day(plan: Plan, vehicle: Vehicle, repeats: int, seed: int) -> tuple[int, int]:
    rng = np.random.default_rng(seed)
    runs = []
    for _ in range(repeats):
        for sid in flown_list(plan):
            runs.append(RunOutcome(sid, outcome(vehicle.fly(plan.u(sid), rng)[0])))
    return confirmed(plan, runs), len(runs)


def conducted_day(
    plan_file: Path, vehicle: Vehicle, budget: int, seed: int, cache: dict, alternatives: dict
) -> tuple[int, int]:
    """One conducted afternoon on its own copy of the plan.  ``cache`` keeps, from day to day, the forecasts of
    the plan's own scenarios in its water and the moves searched: they depend on the plan, not on the runs."""
    rng = np.random.default_rng(seed)
    planned = {s["id"] for s in (lambda p: p.scenarios + p.variants)(load_plan(plan_file))}
    drawn = {k: v for k, v in cache.items() if k in planned}  # a day's moves and new pairs are its own
    with tempfile.TemporaryDirectory(prefix="rapt_afternoon_") as tmp:
        shutil.copytree(plan_file.parent, tmp, dirs_exist_ok=True)
        plan = load_plan(Path(tmp) / "plan.json")
        record = DayRecord(plan.id, alternatives=alternatives)
        runs: list[RunOutcome] = []
        known = afternoon(plan, [], record)
        for k in range(budget):
            known = afternoon(plan, runs, record, known=known)
            answer = decide(known, budget - k, seed=0, cache=drawn, move_cache=cache.setdefault("moves", {}))
            if answer["next"] is None:
                break
            sid = answer["next"]["scenario"]
            plan = load_plan(plan.path)  # a move or a new pair is written into the plan
            runs.append(RunOutcome(sid, outcome(vehicle.fly(plan.u(sid), rng)[0])))
        cache.update({k: v for k, v in drawn.items() if k in planned})
        return confirmed(plan, runs), len(runs)


def side_flips(plan: Plan, vehicle: Vehicle) -> list[tuple[str, float]]:
    """Each flown side's flip probability on this vehicle: 1 - the share of 400 runs that show its outcome."""
    day = afternoon(plan, [])
    rng = np.random.default_rng(12345)
    variant = {v["variant_of"]: v["id"] for v in plan.variants}
    out = []
    for pair in plan.pairs:
        cols = outcome_columns(pair, day.names)
        for sid in pair["scenarios"]:
            flown = variant.get(sid, sid)
            S = vehicle.fly(plan.u(flown), rng, 400)
            ok = ~np.isnan(S[:, 0])
            shows = np.all(S[ok][:, cols] == day.predicted[sid][cols], axis=1)
            out.append((flown, 1.0 - float(shows.mean()) if ok.any() else 1.0))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--days", type=int, default=12, help="Simulated days per policy (seeds 0..days-1).")
    ap.add_argument("--budgets", default="10,14,20", help="Run budgets of the conducted afternoon.")
    ap.add_argument("--noise", type=float, default=1.5, help="The vehicle's execution noise, in the plan's.")
    ap.add_argument("--bias", default="speed=0.95,current_offset=0.1", help="The day's bias the plan does not know.")
    ap.add_argument("--work", type=Path, default=None, help="Directory for the plan (kept: made once).")
    ap.add_argument("--quick", action="store_true", help=f"A {QUICK_BUDGET}-run plan, 3 days, budget 14.")
    args = ap.parse_args(argv)
    days = 3 if args.quick else args.days
    budgets = [14] if args.quick else [int(b) for b in args.budgets.split(",")]
    budget = QUICK_BUDGET if args.quick else BUDGET
    plan_file = make_plan(args.work or Path(tempfile.mkdtemp(prefix="rapt_afternoon_plan_")), budget)
    plan = load_plan(plan_file)
    alternatives = study_alternatives(plan)
    vehicle = Vehicle(plan, args.noise, parse_bias(args.bias))
    flips = side_flips(plan, vehicle)
    print(
        f"plan of {MISSION.relative_to(ROOT)} (budget {BUDGET}, {PAIRS} pairs); vehicle: noise {args.noise:g}x the plan's, bias {args.bias}; {days} days"
    )
    print("side flip probabilities: " + ", ".join(f"{s} {p:.2f}" for s, p in flips))
    print(f"sides flipping with P >= 0.1: {sum(p >= 0.1 for _, p in flips)} of {len(flips)}")
    rows = []
    for label, run in [("each side once", lambda s: fixed_day(plan, vehicle, 1, s)),
                       ("each side twice", lambda s: fixed_day(plan, vehicle, 2, s))]:  # fmt: skip
        t0 = time.perf_counter()
        rows.append((label, [run(s) for s in range(days)], time.perf_counter() - t0))
    cache: dict = {"moves": {}}
    for b in budgets:
        t0 = time.perf_counter()
        rows.append((f"next, budget {b}", [conducted_day(plan_file, vehicle, b, s, cache, alternatives)
                                           for s in range(days)],
                     time.perf_counter() - t0))  # fmt: skip
    twice = next(np.mean([c for c, _ in r]) / np.mean([n for _, n in r]) for label, r, _ in rows if "twice" in label)
    print()
    print(
        "| afternoon | runs (mean) | confirmed of 5 (mean) | all 5 confirmed | confirmed per run | vs twice | s/day |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, r, took in rows:
        c = np.array([x for x, _ in r], dtype=float)
        n = np.array([y for _, y in r], dtype=float)
        per = c.mean() / n.mean()
        print(f"| {label} | {n.mean():.1f} | {c.mean():.2f} | {np.mean(c == 5):.0%} | {per:.3f} | "
              f"{per / twice:.2f}x | {took / days:.1f} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
