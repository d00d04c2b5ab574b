"""After the range day, rehearsed: fly a plan in SIL with an injected bias, then `rapt-plan compare` it.

    python benchmarks/compare.py [--budget 4000] [--pairs 3] [--seed 2] [--workers 2] [--only TEXT] [--quick]

Generates the plan the issue's new user made (`examples/range2017.toml`, 4,000 runs,
`--seed 2 --pairs 3`: 6 scenarios), flies every scenario through the whole
software-in-the-loop stack (`rapt-plan run PLAN --scenario ID --inject-bias ... --log`) for
each case below, runs `rapt-plan compare` on the logs and prints, per case:

* each bias parameter: injected, estimate, standard error, identified, and the error as a
  share of the injected shift (an injected parameter must come back within 20 % of its
  shift; the others must be unidentified or near neutral: within 3 s.e. or 5 % of their prior s.d.);
* the leave-one-log-out mode agreement uncorrected and corrected, the held-out path errors,
  and whether the correction was used (held-out corrected agreement must be >= 90 % and
  never below uncorrected).

A summary table of all cases closes the run.  ``--quick``: the first case on a one-pair
plan (budget 500), about a minute.  ``--vehicle`` also runs part C, a vehicle that is not
the planner's model (:mod:`benchmarks.calibrate`).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import sim.uuv  # noqa: E402
from planner.plan.generate import GenerateConfig, generate  # noqa: E402
from sim.uuv.bias import BIAS_NAMES, NEUTRAL, parse_bias  # noqa: E402

CASES = {  # label: (--inject-bias, stochastic effects on, runs per scenario)
    "speed +15 %": ("speed=1.15", False, 1),
    "current offset +0.3 m/s": ("current_offset=0.3", False, 1),
    "start time +900 s": ("start_time=900", False, 1),
    "steady current across the flood 0.3 m/s": ("current_cross=0.3", False, 1),
    "combined": ("speed=1.15,current_offset=0.3,start_time=900", False, 1),
    # noisy runs are flown twice each (other seeds), as a range team repeats a run it cannot trust
    "stochastic: speed +15 %, offset +0.3 m/s, drift and unmodelled current": (
        "speed=1.15,current_offset=0.3",
        True,
        2,
    ),
}
#: An injected parameter must come back within this share of its shift from neutral.
WITHIN_SHIFT = 0.20
#: A parameter not injected counts as near neutral within this share of its prior s.d. (or 3 s.e.).
NEAR_NEUTRAL = 0.05
#: Held-out corrected mode agreement required.
HELD_OUT_AGREEMENT = 0.90


def rapt_plan() -> list[str]:
    exe = Path(sys.executable).with_name("rapt-plan")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]


def fly_case(
    plan_dir: Path, ids: list[str], logs: Path, text: str, noisy: bool, repeats: int, seed: int, workers: int
) -> tuple[list[Path], float]:
    """Every scenario of the plan flown ``repeats`` times in lock-step SIL with bias ``text``: the logs, seconds taken."""
    logs.mkdir(parents=True, exist_ok=True)
    flights = [(sid, k) for k in range(repeats) for sid in ids]

    def log_of(sid: str, k: int) -> Path:
        return logs / (f"{sid}.mcap" if repeats == 1 else f"{sid}-{k}.mcap")

    def fly(flight: tuple[str, int]) -> None:
        sid, k = flight
        subprocess.run(
            rapt_plan()
            + ["run", str(plan_dir / "plan.json"), "--scenario", sid, "--inject-bias", text]
            + ["--log", str(log_of(sid, k))]
            + (["--stochastic", "--seed", str(seed + 100 * k + ids.index(sid))] if noisy else []),
            check=True,
            capture_output=True,
            cwd=ROOT,
        )

    t0 = time.perf_counter()
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(fly, flights))
    return [log_of(sid, k) for sid, k in flights], time.perf_counter() - t0


def judge(injected, bias: dict) -> tuple[bool, list[tuple]]:
    """Per parameter (name, injected, estimate, s.e., identified, verdict); all verdicts good?"""
    rows, ok = [], True
    for n in BIAS_NAMES:
        inj, v = getattr(injected, n), bias[n]
        est, se, ident = v["estimate"], v["stderr"], v["identified"]
        shift = inj - NEUTRAL[n]
        if shift:
            rel = abs(est - inj) / abs(shift)
            good = ident and rel <= WITHIN_SHIFT
            verdict = f"{rel:.1%} of shift"
        else:  # near neutral: covered by 3 s.e., or a negligible share of what the prior allows
            off = abs(est - NEUTRAL[n])
            prior_sd = v["prior"]["sd"]
            good = not ident or off <= max(3 * se, NEAR_NEUTRAL * prior_sd)
            verdict = "unidentified" if not ident else f"{off / se:.1f} s.e. ({off / prior_sd:.1%} of prior s.d.) off"
        ok &= good
        rows.append((n, inj, est, se, ident, verdict + ("" if good else " FAIL")))
    return ok, rows


def coverage(plan_dir: Path, seeds: int) -> None:
    """The stochastic case's fit over ``seeds`` other noise draws, each run flown by the batch
    simulator (bit-exact with lock-step SIL but for the navigation estimate the log holds):
    how far each identified estimate falls from the truth, in its own standard errors."""
    import numpy as np

    from planner.common.plans import load_plan
    from planner.review.biasfit import fit_bias
    from sim.uuv.scenario import make_scenarios
    from sim.uuv.simulate import TRAJECTORY_FIELDS

    text, _, repeats = CASES[next(k for k in CASES if k.startswith("stochastic"))]
    injected = parse_bias(text)
    plan = load_plan(plan_dir)
    m, ids = plan.mission, [s["id"] for s in plan.scenarios]
    cols = [
        TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "heading", "energy_hj", "surfaced", "speed", "yaw_rate")
    ]
    cmd = [TRAJECTORY_FIELDS.index(k) for k in ("heading_cmd", "speed_cmd")]

    class Run:
        def __init__(self, tr):
            self.steps = tr[:, cols]
            self.setpoints = np.column_stack([tr[:, cmd], np.zeros(len(tr))])
            self.setpoints[-1] = np.nan

    z: dict[str, list[float]] = {n: [] for n in BIAS_NAMES}
    t0 = time.perf_counter()
    for draw in range(seeds):
        runs, U = [], []
        for k in range(repeats):
            for i, sid in enumerate(ids):
                u = plan.u(sid)
                r = sim.uuv.simulate(
                    m, u[None], seed=1000 * (draw + 1) + 100 * k + i, stochastic=True, trajectories=True, bias=injected
                )
                runs.append(Run(r.trajectory(0)))
                U.append(u)
        fit = fit_bias(m, runs, [float(t) for t in make_scenarios(m, np.array(U)).start_time], seed=draw)
        for n, v in fit.to_dict().items():
            if v["identified"]:
                z[n].append((v["estimate"] - getattr(injected, n)) / v["stderr"])
    print(
        f"\n## Standard errors against the truth: the stochastic case over {seeds} noise draws ({time.perf_counter() - t0:.0f} s)"
    )
    print("| parameter | identified in | RMS (estimate - truth) / s.e. | largest abs. |")
    print("|---|---:|---:|---:|")
    for n, zs in z.items():
        a = np.abs(np.array(zs))
        rms = f"{np.sqrt(np.mean(a**2)):.2f}" if a.size else "-"
        big = f"{a.max():.1f}" if a.size else "-"
        print(f"| {n} | {a.size} of {seeds} | {rms} | {big} |")


def report_case(label: str, text: str, noisy: bool, c: dict, timing: str) -> tuple:
    """Print one case's comparison ``c`` (``comparison.json``) against the bias ``text`` injected,
    under its heading and ``timing`` line: the parameter table, held-out agreement and path error,
    the correction and end conditions.  Returns the case's row of the summary."""
    params_ok, rows = judge(parse_bias(text), c["bias"])
    print(f"\n## {label}: --inject-bias {text}" + (" --stochastic" if noisy else ""))
    print(timing)
    print("| parameter | injected | estimate | std. error | identified | verdict |")
    print("|---|---:|---:|---:|:---:|---|")
    for n, inj, est, se, ident, verdict in rows:
        print(f"| {n} | {inj:g} | {est:.5g} | {se:.2g} | {'yes' if ident else 'no'} | {verdict} |")
    cv = c["cross_validation"]
    held, path = cv["held_out_mode_agreement"], cv["held_out_path_error_m"]
    cv_ok = held["corrected"] is not None and held["corrected"] >= HELD_OUT_AGREEMENT
    cv_ok &= held["uncorrected"] is None or held["corrected"] >= held["uncorrected"]
    print(
        f"held-out (leave one log out) mode agreement: uncorrected {held['uncorrected']:.0%}, "
        f"corrected {held['corrected']:.0%} over {held['runs']} runs; held-out path error "
        f"{path['uncorrected']:.1f} m -> {path['corrected']:.1f} m"
    )
    print(f"{c['correction']['note']}")
    ends = c["bias_fit"]["end_conditions"]
    print(
        f"end conditions: {ends.get('logs_with_end', 0)} logged ends, chosen bias: {ends.get('chosen')} "
        f"(reproduces {ends.get('ends_reproduced_by_chosen', '-')} of them)"
    )
    brier = brier_held(c)
    noise = (c["forecast"].get("day_noise") or {}).get("note", "")
    print(
        f"Brier score for held: corrected forecast (day's noise) {_b(brier[0])}, under the plan's assumed noise "
        f"{_b(brier[1])}, deterministic correction {_b(brier[2])}; day's noise: {noise}"
    )
    return (label, params_ok, held, path, c["correction"]["used"], cv_ok, brier)


def brier_held(c: dict) -> tuple[float | None, float | None, float | None]:
    """A comparison's Brier scores for "the predicted mode held": the corrected forecast (drawn with the day's
    fitted noise), the same under the plan's assumed noise, and the deterministic corrected prediction."""
    b = c["forecast"]["brier"]
    assumed = b.get("corrected_assumed_noise", b["corrected"])
    return b["corrected"]["held"], assumed["held"], b["deterministic_corrected"]["held"]


def _b(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def print_summary(summary: list[tuple]) -> None:
    """The closing table: one row per case from :func:`report_case`."""
    print("\n## Summary")
    print(
        "| case | parameters within 20 % of shift, others neutral | held-out agreement uncorrected -> corrected "
        "| held-out path error (m) | correction used | >= 90 % and never below "
        "| Brier held: forecast (day's noise) / assumed noise / deterministic |"
    )
    print("|---|:---:|---:|---:|:---:|:---:|---:|")
    for label, params_ok, held, path, used, cv_ok, brier in summary:
        print(
            f"| {label} | {'yes' if params_ok else 'NO'} | {held['uncorrected']:.0%} -> {held['corrected']:.0%} "
            f"| {path['uncorrected']:.1f} -> {path['corrected']:.1f} | {'yes' if used else 'no'} "
            f"| {'yes' if cv_ok else 'NO'} | {' / '.join(_b(v) for v in brier)} |"
        )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=None, help="search budget of the plan (default 4000; --quick: 500)")
    ap.add_argument("--pairs", type=int, default=None, help="pairs in the plan (default 3; --quick: 1)")
    ap.add_argument("--seed", type=int, default=2, help="seed of the plan and of every run")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", default="", help="Run only the cases whose label contains this text.")
    ap.add_argument("--quick", action="store_true", help="the first case only, from a one-pair plan (about a minute)")
    ap.add_argument("--coverage", type=int, default=8, help="noise seeds of the s.e. coverage check (0: skip)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the plan, logs and comparisons in this directory")
    ap.add_argument("--vehicle", action="store_true", help="also part C: calibrate a vehicle that is not the model")
    args = ap.parse_args(argv)
    if args.budget is None:
        args.budget = 500 if args.quick else 4000
    if args.pairs is None:
        args.pairs = 1 if args.quick else 3
    cases = [label for label in CASES if args.only in label] if args.only else list(CASES)
    if args.quick and not args.only:
        cases = cases[:1]
    mission_file = ROOT / "examples" / "range2017.toml"
    summary = []
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(scratch) if args.keep is None else args.keep
        tmp.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        plan = generate(
            sim.uuv.load_mission(mission_file),
            mission_file,
            tmp / "plan",
            GenerateConfig(budget=args.budget, batch_size=250, pairs=args.pairs, dithers=0, seed=args.seed),
        )
        ids = [s["id"] for s in plan["scenarios"]]
        print(f"plan: {len(ids)} scenarios in {len(plan['pairs'])} pairs ({time.perf_counter() - t0:.0f} s)")
        for label in cases:
            text, noisy, repeats = CASES[label]
            logs = tmp / f"case{list(CASES).index(label)}"
            paths, t_fly = fly_case(tmp / "plan", ids, logs, text, noisy, repeats, args.seed, args.workers)
            t0 = time.perf_counter()
            subprocess.run(
                rapt_plan()
                + ["compare", str(tmp / "plan"), *map(str, paths)]
                + ["--out", str(logs / "cmp"), "--seed", str(args.seed)],
                check=True,
                capture_output=True,
                cwd=ROOT,
            )
            t_cmp = time.perf_counter() - t0
            c = json.loads((logs / "cmp" / "comparison.json").read_text())
            timing = f"{len(paths)} SIL runs in {t_fly:.0f} s ({args.workers} at a time); compare in {t_cmp:.0f} s"
            summary.append(report_case(label, text, noisy, c, timing))
        if args.coverage and not args.quick:
            coverage(tmp / "plan", args.coverage)
    print_summary(summary)
    if args.vehicle:
        from benchmarks import calibrate

        calibrate.main([])


if __name__ == "__main__":
    main()
