"""Search quality at equal budgets: S-NDV against space-filling designs and peer learners.

What it measures
----------------
Every method gets the same budget of evaluations of a synthetic system whose
performance boundaries are known exactly (``rapt.testfunctions``), in batches of 100,
for several seeds.  The samples are scored with ``rapt.metrics.quality_table`` against
a boundary band of width ``D_eps`` (section 3.6.2 of Mullins 2018, Table 3.1):

* precision - share of the samples inside the band (distance to the boundary < D_eps);
* coverage - share of the band within D_eps of an in-band sample;
* mean distance - average distance of the samples to the boundary;
* time - wall time of one whole search (proposals *and* evaluations), in this process,
  one search at a time.

For systems with several outputs (composite8d) each figure is the mean over outputs.

Systems, budgets and D_eps (``rapt.testfunctions.registry.REFERENCE_SETTINGS``): the budgets are the issue's
(2-D: 1000, 3-D: 3000, 7-D screened and 8-D composite: 10000).  The paper does not
state its D_eps, but its Table 3.1 Sobol coverages (32 % in 2-D, 1.3 % in 3-D) show a
band narrow enough that a space-filling design covers well under half of it.  D_eps is
chosen the same way here, and the script prints the measured Sobol coverage beside
each D_eps: it must stay below 40 %, otherwise every method covers everything and
coverage says nothing.

Methods: rapt's ``random``, ``sobol``, ``lhs``, ``nndv``, ``s-ndv`` and (2-D only)
``gpr`` through ``rapt.search``; the dissertation's own peer, ``lola-voronoi``
(``rapt.samplers.lola_voronoi``, Crombecq et al. 2011; no target applies to it); and two
peers from ``benchmarks/peers.py``:
python-adaptive (``Learner2D`` / ``LearnerND``, where it runs; it is deterministic, so
its seeds agree) and random-forest uncertainty sampling, the strong active-learning
baseline: after every batch a 50-tree forest per output is refitted on all samples and
the batch takes the 10x-oversampled random candidates of highest uncertainty - class
entropy for a categorical output, the across-tree standard deviation of a regression
forest for a continuous one (stronger on Custom2D than the entropy of 8 quantile bins),
each output's score divided by its maximum over the candidates before summing.

How to read the table
---------------------
``P/Sobol`` and ``C/Sobol`` are the ratios of the method's mean precision and mean
coverage to Sobol's on the same system.  The ``target`` column judges the s-ndv rows:
on the 2-D and 3-D systems PASS needs P/Sobol >= 3 and C/Sobol >= 1.8; on the 7-D
screened and 8-D composite systems P/Sobol >= 2 and C/Sobol >= 1.  Under the table:

* the D_eps used per system and Sobol's coverage there (must be < 40 %);
* S-NDV against the uncertainty learner: ``P s-ndv/unc`` (precision ratio; "matches"
  means >= 0.9) and ``time unc/s-ndv`` (the learner's time over S-NDV's; the target
  is >= 10, i.e. S-NDV at a tenth of the time or less);
* the 2-D NNDV search time (1000 samples, batch 100) against the paper's 0.645 s
  (MATLAB) and the 0.3 s target.

Usage::

    python benchmarks/search_quality.py                 # 3 seeds, full budgets (~15 min on 2 cores)
    python benchmarks/search_quality.py --quick         # 1 seed, 7-D/8-D at 3000 samples, no GPR
    python benchmarks/search_quality.py --systems plates2d plates3d --seeds 5
    python benchmarks/search_quality.py --methods sobol s-ndv uncertainty python-adaptive   # the peers only

With ``--quick --systems custom2d plates2d plates3d`` the peers-only run takes one seed on
the systems every peer runs on (python-adaptive stops at 3-D), at their full budgets.

The exit code is 0 whatever the verdicts (it is a report, not a test); only an
exception ends it otherwise.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
sys.path.insert(0, str(_HERE.parent))

import peers  # noqa: E402

import rapt  # noqa: E402
from rapt.metrics import quality_table  # noqa: E402
from rapt.testfunctions.registry import REFERENCE_SETTINGS, get_system, search_output_types  # noqa: E402

BATCH = 100
#: A method other than sobol / s-ndv / uncertainty whose first run takes longer than
#: this keeps that one run and skips its remaining seeds (GPR on Custom2D).
SLOW_SECONDS = 60.0
#: Sobol coverage at the budget must stay below this for D_eps to be informative.
MAX_SOBOL_COVERAGE = 0.40
#: "S-NDV matches the uncertainty learner's precision" means this ratio or more.
MATCH_RATIO = 0.9
#: S-NDV must take at most 1/TIME_FACTOR of the uncertainty learner's time.
TIME_FACTOR = 10.0
PAPER_NNDV_2D_SECONDS = 0.645
TARGET_NNDV_2D_SECONDS = 0.3


@dataclass(frozen=True)
class SystemSpec:
    budget: int
    quick_budget: int
    d_eps: float
    p_target: float
    c_target: float
    why: str


def _spec(name: str, quick_budget: int, p_target: float, c_target: float, why: str) -> SystemSpec:
    """Budget and D_eps come from ``rapt.testfunctions.registry.REFERENCE_SETTINGS`` (one source of truth)."""
    budget, d_eps = REFERENCE_SETTINGS[name]
    return SystemSpec(budget, min(quick_budget, budget), d_eps, p_target, c_target, why)


SYSTEMS: dict[str, SystemSpec] = {
    "custom2d": _spec("custom2d", 1000, 3.0, 1.8, "1 % of the side; Table 3.1's Sobol covers ~32 % at 1000"),
    "plates2d": _spec("plates2d", 1000, 3.0, 1.8, "1 % of the side; Table 3.1's Sobol covers ~32 % at 1000"),
    "plates3d": _spec("plates3d", 3000, 3.0, 1.8, "narrow, as the paper's Plates3D (Sobol 1.3 % at 3000)"),
    "plates3d-screened": _spec(
        "plates3d-screened", 3000, 2.0, 1.0, "same band as plates3d (same boundary and active inputs)"
    ),
    "composite8d": _spec(
        "composite8d", 3000, 2.0, 1.0, "per 2-D subfunction; 10000 samples fill each 2-D block densely"
    ),
}

RAPT_METHODS = ("random", "sobol", "lhs", "nndv", "s-ndv", "gpr", "lola-voronoi")
METHODS = ("random", "sobol", "lhs", "nndv", "s-ndv", "gpr", "lola-voronoi", "python-adaptive", "uncertainty")
#: Methods that always run every seed (the targets are about them).
FULL_SEEDS = {"sobol", "s-ndv", "uncertainty"}


@dataclass
class Result:
    method: str
    precision: list[float] = field(default_factory=list)
    coverage: list[float] = field(default_factory=list)
    mean_distance: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    note: str = ""
    na: str = ""  # why the method did not run here

    @property
    def ran(self) -> bool:
        return bool(self.precision)

    def mean(self, key: str) -> float:
        return float(np.mean(getattr(self, key)))

    def std(self, key: str) -> float:
        return float(np.std(getattr(self, key)))


# ---------------------------------------------------------------------------- running
def run_once(method: str, system, budget: int, seed: int) -> tuple[np.ndarray, float]:
    """One search; returns the evaluated unit-cube samples and the wall time in seconds."""
    start = time.perf_counter()
    if method in RAPT_METHODS:
        study = rapt.search(
            system,
            [(0.0, 1.0)] * system.dim,
            budget,
            method=method,
            batch_size=BATCH,
            seed=seed,
            output_types=list(search_output_types(system)),
        )
        X = study.X
    elif method == "python-adaptive":
        X = peers.python_adaptive_search(system, budget, BATCH, seed)
    elif method == "uncertainty":
        X = peers.uncertainty_search(system, budget, BATCH, seed)
    else:  # pragma: no cover - guarded by argparse
        raise ValueError(method)
    return X, time.perf_counter() - start


def not_applicable(
    method: str, system, adaptive_ok: bool, nd_probe: dict | None, quick: bool, explicit_methods: bool
) -> str:
    """Why ``method`` is not run on ``system`` ('' when it is)."""
    if method == "gpr":
        if system.dim != 2:
            return "n/a (GPR only on the 2-D systems: O(n^3), infeasible at 3000-10000 samples)"
        if quick and not explicit_methods:
            return "skipped in --quick (name it in --methods to run it)"
    if method == "python-adaptive":
        if not adaptive_ok:
            return "n/a (adaptive not installed)"
        if system.dim > 3:
            probe = ""
            if nd_probe is not None:
                probe = f"; measured in 7-D: {nd_probe['points']} points in {nd_probe['at']:.1f} s"
                if not nd_probe["finished"]:
                    probe += f", no more by the {nd_probe['limit']:.0f} s limit"
            return f"n/a (LearnerND triangulation does not scale to 7-8D{probe})"
        if system.n_outputs != 1:
            return "n/a (learners take a scalar function)"
    return ""


def evaluate(
    system_name: str,
    spec: SystemSpec,
    budget: int,
    methods: list[str],
    seeds: list[int],
    adaptive_ok: bool,
    nd_probe: dict | None,
    quick: bool,
    explicit_methods: bool,
    log,
) -> dict[str, Result]:
    system = get_system(system_name)
    results: dict[str, Result] = {}
    for method in methods:
        res = Result(method)
        results[method] = res
        res.na = not_applicable(method, system, adaptive_ok, nd_probe, quick, explicit_methods)
        if res.na:
            continue
        for i, seed in enumerate(seeds):
            X, seconds = run_once(method, system, budget, seed)
            if X.shape[0] != budget:
                res.note = f"returned {X.shape[0]} samples"
            q = quality_table(system, X, spec.d_eps, seed=0)  # same band reference points for every method
            res.precision.append(q["precision"])
            res.coverage.append(q["coverage"])
            res.mean_distance.append(q["mean_distance"])
            res.seconds.append(seconds)
            log(
                f"  {system_name:18s} {method:16s} seed {seed}: P={q['precision']:.3f} C={q['coverage']:.3f} "
                f"t={seconds:.2f}s"
            )
            if i == 0 and len(seeds) > 1 and method not in FULL_SEEDS and seconds > SLOW_SECONDS:
                res.note = f"1 seed only: the run took {seconds:.0f} s > {SLOW_SECONDS:.0f} s"
                break
        if method == "python-adaptive" and len(seeds) > 1:
            res.note = res.note or "deterministic: every seed gives the same samples"
    return results


def warm_up() -> None:
    """Pay import and first-call costs (sklearn, scipy) before anything is timed."""
    system = get_system("plates2d")
    for method in ("sobol", "nndv", "s-ndv"):
        run_once(method, system, 300, 0)
    peers.uncertainty_search(system, 300, BATCH, 0)
    quality_table(system, np.random.default_rng(0).random((100, 2)), 0.01)


# --------------------------------------------------------------------------- printing
def _pm(values: list[float], digits: int = 3) -> str:
    if len(values) > 1:
        return f"{np.mean(values):.{digits}f} ±{np.std(values):.{digits}f}"
    return f"{np.mean(values):.{digits}f}"


def _time(values: list[float]) -> str:
    m = float(np.mean(values))
    text = f"{m:.3f}" if m < 10 else f"{m:.1f}"
    if len(values) > 1:
        s = float(np.std(values))
        text += f" ±{s:.3f}" if m < 10 else f" ±{s:.1f}"
    return text


def verdict(spec: SystemSpec, p_ratio: float, c_ratio: float) -> str:
    ok = p_ratio >= spec.p_target and c_ratio >= spec.c_target
    word = "PASS" if ok else "FAIL"
    return f"{word} (P>={spec.p_target:g}x, C>={spec.c_target:g}x)"


#: Columns of the main table; an n/a row's message spans those from "precision" on.
TABLE_HEADERS = [
    "system",
    "method",
    "n",
    "seeds",
    "precision",
    "coverage",
    "mean dist",
    "time/search s",
    "P/Sobol",
    "C/Sobol",
    "target (s-ndv)",
]


def print_table(
    all_results: dict[str, dict[str, Result]], specs: dict[str, SystemSpec], budgets: dict[str, int], seeds: list[int]
) -> list[str]:
    """Print the table; return the failed targets as text lines."""
    rows, notes, failures = table_rows(all_results, specs, budgets)
    print_rows(TABLE_HEADERS, rows)
    if notes:
        print("Notes:")
        for n in notes:
            print(f"  - {n}")
    return failures


def table_rows(
    all_results: dict[str, dict[str, Result]], specs: dict[str, SystemSpec], budgets: dict[str, int]
) -> tuple[list[list[str]], list[str], list[str]]:
    """The table's cells (an empty row between systems), its notes and the failed s-ndv targets."""
    rows: list[list[str]] = []
    notes: list[str] = []
    failures: list[str] = []
    for name, results in all_results.items():
        spec = specs[name]
        sobol = results.get("sobol")
        sp = sobol.mean("precision") if sobol and sobol.ran else np.nan
        sc = sobol.mean("coverage") if sobol and sobol.ran else np.nan
        for method, res in results.items():
            if not res.ran:
                rows.append([name, method, str(budgets[name]), "-", res.na, "", "", "", "", "", ""])
                continue
            p, c = res.mean("precision"), res.mean("coverage")
            pr, cr = p / sp if sp > 0 else np.nan, c / sc if sc > 0 else np.nan
            target = ""
            if method == "s-ndv":
                target = verdict(spec, pr, cr) if np.isfinite(pr) and np.isfinite(cr) else "n/a (no sobol row)"
                if target.startswith("FAIL"):
                    failures.append(
                        f"{name}: s-ndv P/Sobol={pr:.2f} (need {spec.p_target:g}), "
                        f"C/Sobol={cr:.2f} (need {spec.c_target:g})"
                    )
            rows.append(
                [
                    name,
                    method,
                    str(budgets[name]),
                    str(len(res.precision)),
                    _pm(res.precision),
                    _pm(res.coverage),
                    f"{res.mean('mean_distance'):.4f}",
                    _time(res.seconds),
                    f"{pr:.2f}",
                    f"{cr:.2f}",
                    target,
                ]
            )
            if res.note:
                notes.append(f"{name} / {method}: {res.note}")
        rows.append([])
    return rows, notes, failures


def print_rows(headers: list[str], rows: list[list[str]]) -> None:
    """The rows in aligned columns under ``headers`` (text left, figures right); an n/a row's
    message runs on from the fifth column unaligned."""
    widths = [len(h) for h in headers]
    for row in rows:
        for i, cell in enumerate(row):
            if i == 4 and row[5:] == [""] * 6:  # an n/a message spans the numeric columns
                continue
            widths[i] = max(widths[i], len(cell))
    line = "  ".join(h.ljust(w) if i < 2 or i == 10 else h.rjust(w) for i, (h, w) in enumerate(zip(headers, widths)))
    print(line)
    print("-" * len(line))
    for row in rows:
        if not row:
            print()
            continue
        if row[5:] == [""] * 6:
            print(
                "  ".join(
                    cell.ljust(w) if i < 2 else cell.rjust(w) for i, (cell, w) in enumerate(zip(row[:4], widths[:4]))
                )
                + "  "
                + row[4]
            )
            continue
        print(
            "  ".join(
                cell.ljust(w) if i < 2 or i == 10 else cell.rjust(w) for i, (cell, w) in enumerate(zip(row, widths))
            ).rstrip()
        )


def print_d_eps(all_results, specs, budgets) -> list[str]:
    print("\nBoundary width D_eps per system (Sobol coverage at the budget must be < 40 %):")
    failures = []
    for name, results in all_results.items():
        spec = specs[name]
        sobol = results.get("sobol")
        if sobol is None or not sobol.ran:
            print(f"  {name:18s} D_eps={spec.d_eps:<6g} n={budgets[name]:<6d} Sobol coverage: not run")
            continue
        cov = sobol.mean("coverage")
        worst = max(sobol.coverage)
        ok = worst < MAX_SOBOL_COVERAGE
        if not ok:
            failures.append(f"{name}: Sobol coverage {worst:.1%} at D_eps={spec.d_eps:g} is not < 40 %")
        print(
            f"  {name:18s} D_eps={spec.d_eps:<6g} n={budgets[name]:<6d} Sobol coverage {cov:6.1%} "
            f"(max over seeds {worst:.1%}) {'OK' if ok else 'TOO WIDE'}  - {spec.why}"
        )
    return failures


def print_uncertainty(all_results) -> list[str]:
    print(
        f"\nS-NDV against the uncertainty learner (match: P s-ndv/unc >= {MATCH_RATIO:g}; "
        f"time: unc/s-ndv >= {TIME_FACTOR:g}):"
    )
    failures = []
    for name, results in all_results.items():
        s, u = results.get("s-ndv"), results.get("uncertainty")
        if not (s and u and s.ran and u.ran):
            continue
        pr = s.mean("precision") / u.mean("precision")
        tr = u.mean("seconds") / s.mean("seconds")
        p_ok, t_ok = pr >= MATCH_RATIO, tr >= TIME_FACTOR
        word = "PASS" if p_ok and t_ok else "FAIL"
        why = []
        if not p_ok:
            why.append("precision below the learner's")
        if not t_ok:
            why.append("less than 10x faster")
        print(
            f"  {name:18s} P s-ndv/unc = {pr:5.2f} ({s.mean('precision'):.3f} vs {u.mean('precision'):.3f})   "
            f"time unc/s-ndv = {tr:6.1f}x ({u.mean('seconds'):.2f} s vs {s.mean('seconds'):.2f} s)   "
            f"{word}{' (' + '; '.join(why) + ')' if why else ''}"
        )
        if word == "FAIL":
            failures.append(f"{name}: vs uncertainty P ratio {pr:.2f}, time ratio {tr:.1f}x ({'; '.join(why)})")
    return failures


def print_nndv_timing(all_results, seeds: list[int]) -> list[str]:
    print(
        f"\n2-D NNDV search time (1000 samples, batch {BATCH}; paper: {PAPER_NNDV_2D_SECONDS} s in MATLAB, "
        f"target: {TARGET_NNDV_2D_SECONDS} s):"
    )
    timings: dict[str, list[float]] = {}
    for name in ("custom2d", "plates2d"):
        res = all_results.get(name, {}).get("nndv")
        if res is not None and res.ran:
            timings[name] = res.seconds
    if not timings:  # no 2-D system in this run: time it on its own
        system = get_system("plates2d")
        timings["plates2d"] = [run_once("nndv", system, 1000, s)[1] for s in seeds]
    failures = []
    for name, secs in timings.items():
        m, worst = float(np.mean(secs)), float(np.max(secs))
        word = "PASS" if m < TARGET_NNDV_2D_SECONDS else "FAIL"
        print(
            f"  {name:18s} mean {m:.3f} s (max {worst:.3f} s) over {len(secs)} run(s): "
            f"{PAPER_NNDV_2D_SECONDS / m:.1f}x faster than the paper's {PAPER_NNDV_2D_SECONDS} s; "
            f"{word} against the {TARGET_NNDV_2D_SECONDS} s target"
        )
        if word == "FAIL":
            failures.append(f"{name}: 2-D NNDV search takes {m:.3f} s, not < {TARGET_NNDV_2D_SECONDS} s")
    return failures


# ------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per method (default 3)")
    parser.add_argument(
        "--quick", action="store_true", help="1 seed, 7-D/8-D budgets 3000, GPR skipped: a fast look, not the verdict"
    )
    parser.add_argument("--systems", nargs="+", choices=list(SYSTEMS), default=list(SYSTEMS))
    parser.add_argument("--methods", nargs="+", choices=list(METHODS), default=None)
    parser.add_argument(
        "--probe-seconds", type=float, default=30.0, help="time allowed to the LearnerND 7-D probe (default 30)"
    )
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    seeds = [0] if args.quick else list(range(args.seeds))
    explicit_methods = args.methods is not None
    methods = list(args.methods or METHODS)
    if "sobol" not in methods:
        methods.insert(0, "sobol")  # every ratio is to Sobol
    budgets = {n: (SYSTEMS[n].quick_budget if args.quick else SYSTEMS[n].budget) for n in args.systems}

    t_start = time.perf_counter()
    print("RAPT search quality at equal budgets")
    print(
        f"python {platform.python_version()} on {platform.machine()}, {os.cpu_count()} cores; "
        f"numpy {np.__version__}; seeds {seeds}; batch {BATCH}; "
        f"{'QUICK (targets are defined at the full budgets)' if args.quick else 'full budgets'}"
    )
    adaptive_ok = peers.adaptive_available()
    nd_probe = None
    if adaptive_ok and "python-adaptive" in methods and any(get_system(n).dim > 3 for n in args.systems):
        print(
            f"Probing python-adaptive LearnerND on the 7-D screened system (batches of 20, "
            f"up to 500 points, {args.probe_seconds:g} s limit) ...",
            flush=True,
        )
        nd_probe = peers.probe_learnernd("plates3d-screened", args.probe_seconds)
        print(
            f"  reached {nd_probe['points']} points in {nd_probe['at']:.1f} s"
            f"{'' if nd_probe['finished'] else ' before the limit stopped it'}",
            flush=True,
        )
    warm_up()

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    all_results: dict[str, dict[str, Result]] = {}
    for name in args.systems:
        print(f"Running {name} ({budgets[name]} samples) ...", file=sys.stderr, flush=True)
        all_results[name] = evaluate(
            name, SYSTEMS[name], budgets[name], methods, seeds, adaptive_ok, nd_probe, args.quick, explicit_methods, log
        )

    print()
    failures = print_table(all_results, SYSTEMS, budgets, seeds)
    failures += print_d_eps(all_results, SYSTEMS, budgets)
    if "uncertainty" in methods and "s-ndv" in methods:
        failures += print_uncertainty(all_results)
    failures += print_nndv_timing(all_results, seeds)
    print("\nTargets failed:" if failures else "\nTargets failed: none")
    for f in failures:
        print(f"  - {f}")
    print(f"\nTotal run time {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
