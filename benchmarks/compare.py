"""After the range day, rehearsed: fly a plan in SIL with an injected bias, then `rapt-plan compare` it.

    python benchmarks/compare.py [--budget 1000] [--pairs 4] [--workers 2] [--only TEXT] [--quick]

Generates a plan of the 2017 range mission, flies every scenario through the whole
software-in-the-loop stack (`rapt-plan run PLAN --scenario ID --inject-bias ... --log`) for
each injected bias below, runs `rapt-plan compare` on the logs and prints, per case, the
injected against the recovered value of each bias parameter (with its standard error)
and the mode agreement of the predictions as planned and with the fitted bias.

``--quick`` prints the same table for the first case only, from a plan of one pair
(budget 500, 2 scenarios): well under a minute on 2 cores.
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
from planner.generate import GenerateConfig, generate  # noqa: E402
from sim.uuv.bias import BIAS_NAMES, Bias, parse_bias  # noqa: E402

CASES = {  # label: (--inject-bias, stochastic effects on)
    "issue 7: faster vehicle, tide offset": ("speed=1.15,current_offset=0.3", False),
    "all six parameters": (
        "speed=1.1,current_scale=0.8,current_offset=-0.2,heading=3,battery=1.2,start_time=1800",
        False,
    ),
    "issue 7 with navigation drift and current perturbations": ("speed=1.15,current_offset=0.3", True),
}


def rapt_plan() -> list[str]:
    exe = Path(sys.executable).with_name("rapt-plan")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=None, help="search budget of the plan (default 1000; --quick: 500)")
    ap.add_argument("--pairs", type=int, default=None, help="pairs in the plan (default 4; --quick: 1)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="", help="Run only the cases whose label contains this text.")
    ap.add_argument("--quick", action="store_true", help="the first case only, from a one-pair plan (under a minute)")
    args = ap.parse_args()
    if args.budget is None:
        args.budget = 500 if args.quick else 1000
    if args.pairs is None:
        args.pairs = 1 if args.quick else 4
    cases = list(CASES)
    if args.only:
        cases = [label for label in cases if args.only in label]
    elif args.quick:
        cases = cases[:1]
    mission_file = ROOT / "examples" / "range2017.toml"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
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
            text, noisy = CASES[label]
            logs = tmp / f"case{list(CASES).index(label)}"
            logs.mkdir()

            def fly(sid: str, text: str = text, logs: Path = logs, noisy: bool = noisy) -> float:
                start = time.perf_counter()
                subprocess.run(
                    rapt_plan()
                    + [
                        "run",
                        str(tmp / "plan" / "plan.json"),
                        "--scenario",
                        sid,
                        "--inject-bias",
                        text,
                        "--log",
                        str(logs / f"{sid}.mcap"),
                    ]
                    + (["--stochastic", "--seed", str(args.seed + ids.index(sid))] if noisy else []),
                    check=True,
                    capture_output=True,
                    cwd=ROOT,
                )
                return time.perf_counter() - start

            t0 = time.perf_counter()
            with ThreadPoolExecutor(args.workers) as pool:
                list(pool.map(fly, ids))
            t_fly = time.perf_counter() - t0
            t0 = time.perf_counter()
            subprocess.run(
                rapt_plan()
                + [
                    "compare",
                    str(tmp / "plan"),
                    *[str(logs / f"{s}.mcap") for s in ids],
                    "--out",
                    str(logs / "cmp"),
                    "--seed",
                    str(args.seed),
                ],
                check=True,
                capture_output=True,
                cwd=ROOT,
            )
            t_cmp = time.perf_counter() - t0
            c = json.loads((logs / "cmp" / "comparison.json").read_text())
            injected = parse_bias(text)
            print(f"\n## {label}: --inject-bias {text}" + (" --stochastic" if noisy else ""))
            print(f"{len(ids)} SIL runs in {t_fly:.0f} s ({args.workers} at a time); compare in {t_cmp:.0f} s")
            print("| parameter | injected | recovered | std. error | error / injected shift |")
            print("|---|---:|---:|---:|---:|")
            neutral = Bias()
            for n in BIAS_NAMES:
                inj, est = getattr(injected, n), c["bias"][n]["estimate"]
                se = c["bias"][n]["stderr"]
                shift = inj - getattr(neutral, n)
                rel = f"{abs(est - inj) / abs(shift):.2%}" if shift else f"(abs. {abs(est - inj):.2g})"
                print(f"| {n} | {inj:g} | {est:.5g} | {'n/a' if se is None else f'{se:.2g}'} | {rel} |")
            ag = c["mode_agreement"]
            print(
                f"mode agreement over {ag['scenarios']} scenarios: as planned {ag['uncorrected']:.0%}, "
                f"with the fitted bias {ag['corrected']:.0%}"
            )
            flagged = [p["id"] for p in c["pairs"] if p["flagged"]]
            props = [q["id"] for q in c["proposals"] if q["found"]]
            print(f"pairs flagged under the bias: {flagged or 'none'}; adjusted scenarios proposed: {props or 'none'}")
            print(
                f"position residual after the fit {c['bias_fit']['rms_position_m']:.2g} m RMS "
                f"(unbiased model {c['bias_fit']['rms_position_unbiased_m']:.3g} m)"
            )


if __name__ == "__main__":
    main()
