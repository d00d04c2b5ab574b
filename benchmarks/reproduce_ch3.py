"""Table 3.1 and Figure 3.8 of Mullins 2018 reproduced: Sobol, GPR, LOLA-Voronoi, NNDV and S-NDV.

What it measures
----------------
Each method searches Custom2D and Plates2D (1,000 samples) and Plates3D (3,000 samples),
the systems and budgets of Table 3.1, in batches of 100 (the first batch Sobol), driven
through the samplers' ask/tell loop so the wall time is read at every batch.  Scored
with ``rapt.metrics`` against the boundary band of width D_eps
(``REFERENCE_SETTINGS``, as in ``benchmarks/search_quality.py``):

* precision, coverage, mean distance: of the first ``budget`` samples;
* runtime: CPU time of this process, and wall time, of the search up to ``budget``
  samples (proposals and evaluations).  On a shared machine the wall time mostly
  measures the load; run with ``OMP_NUM_THREADS=1`` so that BLAS threads do not thrash;
* convergence: samples needed until coverage first reaches 90 %
  (``rapt.metrics.convergence``, on a grid of 100).  The dissertation does not define
  it in words; its text reads it as the samples "required to reach 90 % coverage"
  (section 3.6.2), and its Sobol figures (1,100 in 2-D, 26,200 in 3-D) exceed the
  budgets, so each search continues past its budget to a horizon (``--horizon-2d``,
  ``--horizon-3d``); "> H" means not reached by the horizon H.  GPR stops earlier
  (``--gpr-horizon``, at its budget on Plates3D): a GP is O(n^3) and, even capped at
  1,000 fitted samples, takes minutes per thousand samples in 3-D.

The paper's D_eps is not stated and differs from ours (its Sobol covers 32 % of the 2-D
band and 1.3 % of the 3-D one; ours about 26 % and 8 %), so the table compares the
ratios to Sobol, ours beside the paper's.  Runtimes are not comparable in absolute terms
(the paper: MATLAB, SUMO's LOLA-Voronoi with a Blind Kriging model); S-NDV is not in
the paper's table (it came later in the chapter).

Figure 3.8: mean distance, precision and coverage against the number of samples, for
Plates2D (top) and Plates3D (bottom), one line per method (mean over seeds), up to the
horizon; ``--png DIR`` writes ``DIR/fig3_8.png``.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/reproduce_ch3.py --png docs/reproduction   # the full run: 2 seeds
    python benchmarks/reproduce_ch3.py --quick                             # 1 seed, horizon = budget, no 3-D GPR

The exit code is 0 whatever the results (a report, not a test).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from rapt.metrics import convergence, coverage_curve  # noqa: E402
from rapt.samplers import METHODS as METHODS_ADAPTIVE  # noqa: E402
from rapt.samplers import make_sampler  # noqa: E402
from rapt.testfunctions.registry import REFERENCE_SETTINGS, get_system, search_output_types  # noqa: E402

BATCH = 100
METHODS = ("sobol", "gpr", "lola-voronoi", "nndv", "s-ndv")
SYSTEMS = ("custom2d", "plates2d", "plates3d")
TARGET = 0.9  # coverage that counts as converged
#: Table 3.1: (precision, coverage, runtime s, convergence samples); None = not in the paper.
PAPER: dict[str, dict[str, tuple[float, float, float, float | None] | None]] = {
    "custom2d": {
        "sobol": (0.064, 0.3176, 0.791, 800),
        "lola-voronoi": (0.0953, 0.490, 27.2, 800),
        "gpr": (0.116, 0.4843, 2.96, 700),
        "nndv": (0.192, 0.592, 0.645, 700),
        "s-ndv": None,
    },
    "plates2d": {
        "sobol": (0.064, 0.317, 0.791, 1100),
        "lola-voronoi": (0.0658, 0.394, 31.9, 960),
        "gpr": (0.116, 0.484, 2.96, 600),
        "nndv": (0.192, 0.592, 0.64, 500),
        "s-ndv": None,
    },
    "plates3d": {
        "sobol": (0.0346, 0.0131, 0.233, 26200),
        "lola-voronoi": (0.0422, 0.01526, 246.0, None),
        "gpr": (0.0743, 0.0264, 32.7, 21300),
        "nndv": (0.1217, 0.0465, 2.12, 12100),
        "s-ndv": None,
    },
}


@dataclass
class Runs:
    """One method on one system: per seed, the figures at the budget and the curves to the horizon."""

    precision: list[float] = field(default_factory=list)
    coverage: list[float] = field(default_factory=list)
    mean_distance: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    converged: list[float] = field(default_factory=list)  # NaN: not by the horizon
    curves: list[np.ndarray] = field(default_factory=list)  # (sizes, 3): mean distance, precision, coverage


def search(system, method: str, seed: int, horizon: int, budget: int) -> tuple[np.ndarray, float, float]:
    """Ask/tell to ``horizon`` samples in batches of 100; the samples, and the wall and CPU seconds to ``budget``."""
    options = {"n_initial": BATCH} if METHODS_ADAPTIVE[method].adaptive else {}
    sampler = make_sampler(method, system.dim, seed=seed, output_types=list(search_output_types(system)), **options)
    start, cpu_start, at_budget, cpu = time.perf_counter(), time.process_time(), np.nan, np.nan
    while sampler.n_told < horizon:
        Q = sampler.ask(min(BATCH, horizon - sampler.n_told))
        sampler.tell(Q, system(Q))
        if sampler.n_told == budget:
            at_budget, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return sampler.X, at_budget, cpu


def measure(name: str, method: str, seeds: list[int], horizon: int, log) -> Runs:
    """Run ``method`` on system ``name`` for every seed and score it at the budget and along the way."""
    system = get_system(name)
    budget, d_eps = REFERENCE_SETTINGS[name]
    sizes = np.arange(BATCH, horizon + 1, BATCH)
    runs = Runs()
    for seed in seeds:
        X, seconds, cpu = search(system, method, seed, horizon, budget)
        d = np.asarray(system.boundary_distance(X), dtype=float).reshape(len(X), -1).mean(axis=1)
        cover = coverage_curve(system, X, d_eps, sizes).mean(axis=1)
        inside = np.cumsum(d < d_eps)[sizes - 1] / sizes
        runs.curves.append(np.column_stack([np.cumsum(d)[sizes - 1] / sizes, inside, cover]))
        at = int(np.searchsorted(sizes, budget))
        runs.mean_distance.append(float(runs.curves[-1][at, 0]))
        runs.precision.append(float(inside[at]))
        runs.coverage.append(float(cover[at]))
        runs.seconds.append(seconds)
        runs.cpu.append(cpu)
        runs.converged.append(float(np.mean(convergence(system, X, d_eps, target=TARGET, step=BATCH))))
        log(
            f"  {name:9s} {method:13s} seed {seed}: P={inside[at]:.3f} C={cover[at]:.3f} t={seconds:.2f}s cpu={cpu:.2f}s "
            f"converged at {runs.converged[-1]:g} (horizon {horizon})"
        )
    return runs


# --------------------------------------------------------------------------- printing
def _conv(values: list[float], horizon: int) -> str:
    """Mean samples to converge; seeds that did not by the horizon are counted beside it."""
    reached = [v for v in values if not np.isnan(v)]
    if not reached:
        return f"> {horizon:,}"
    if len(reached) < len(values):
        return f"{np.mean(reached):,.0f} ({len(values) - len(reached)} of {len(values)} seeds > {horizon:,})"
    return f"{np.mean(values):,.0f}"


def _paper_conv(value: float | None) -> str:
    return "n/a" if value is None else f"{value:,.0f}"


def table(results: dict[str, dict[str, Runs]], horizons: dict[str, int]) -> list[str]:
    """Table 3.1 as markdown lines: ours beside the paper's, with ratios to Sobol."""
    lines = [
        "| system (budget, D_eps) | method | precision | ÷ Sobol (paper) | coverage | ÷ Sobol (paper) "
        "| mean dist | CPU s, wall s (paper) | convergence to 90 % (paper) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, by_method in results.items():
        budget, d_eps = REFERENCE_SETTINGS[name]
        sobol, paper_sobol = by_method["sobol"], PAPER[name]["sobol"]
        assert paper_sobol is not None
        sp, sc = np.mean(sobol.precision), np.mean(sobol.coverage)
        for method, runs in by_method.items():
            p, c = np.mean(runs.precision), np.mean(runs.coverage)
            paper = PAPER[name][method]
            pp = "—" if paper is None else f"{paper[0] / paper_sobol[0]:.1f}×"
            pc = "—" if paper is None else f"{paper[1] / paper_sobol[1]:.1f}×"
            pt = "—" if paper is None else f"{paper[2]:g}"
            pv = "—" if paper is None else _paper_conv(paper[3])
            lines.append(
                f"| {name} ({budget}, {d_eps:g}) | {method} | {p:.1%} | {p / sp:.1f}× ({pp}) | {c:.1%} "
                f"| {c / sc:.1f}× ({pc}) | {np.mean(runs.mean_distance):.4f} | {np.mean(runs.cpu):.2f}, {np.mean(runs.seconds):.2f} ({pt}) "
                f"| {_conv(runs.converged, len(runs.curves[0]) * BATCH)} ({pv}) |"
            )
    return lines


def figure(results: dict[str, dict[str, Runs]], horizons: dict[str, int], path: Path) -> None:
    """Figure 3.8: mean distance, precision, coverage vs samples; Plates2D above, Plates3D below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [n for n in ("plates2d", "plates3d") if n in results]
    fig, axes = plt.subplots(len(shown), 3, figsize=(13, 3.6 * len(shown)), squeeze=False)
    titles = ("mean distance to the boundary", "precision", "coverage")
    for row, name in zip(axes, shown):
        for method, runs in results[name].items():
            mean = np.mean(runs.curves, axis=0)
            sizes = np.arange(1, len(mean) + 1) * BATCH
            for k, ax in enumerate(row):
                ax.plot(sizes, mean[:, k], label=method, color=f"C{METHODS.index(method)}")
        for k, ax in enumerate(row):
            ax.axvline(REFERENCE_SETTINGS[name][0], color="grey", ls=":", lw=1)
            ax.set_title(f"{name}: {titles[k]}")
            ax.set_xlabel("samples")
            ax.grid(alpha=0.3)
        row[0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 (default 2)")
    parser.add_argument("--quick", action="store_true", help="1 seed, horizon = budget, no GPR on Plates3D")
    parser.add_argument("--systems", nargs="+", choices=SYSTEMS, default=list(SYSTEMS))
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument("--horizon-2d", type=int, default=3000, help="samples run for convergence in 2-D")
    parser.add_argument("--horizon-3d", type=int, default=6000, help="samples run for convergence in 3-D")
    parser.add_argument("--gpr-horizon", type=int, default=2000, help="GPR's horizon (never below its budget)")
    parser.add_argument("--png", type=Path, default=None, help="write DIR/fig3_8.png")
    args = parser.parse_args(argv)
    seeds = [0] if args.quick else list(range(args.seeds))
    methods = ["sobol"] + [m for m in args.methods if m != "sobol"]  # every ratio is to Sobol
    horizons = {}
    for name in args.systems:
        budget = REFERENCE_SETTINGS[name][0]
        horizons[name] = (
            budget if args.quick else max(budget, args.horizon_3d if name == "plates3d" else args.horizon_2d)
        )

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    start = time.perf_counter()
    print(f"Table 3.1 / Figure 3.8 reproduction; seeds {seeds}; batch {BATCH}; horizons {horizons}")
    results: dict[str, dict[str, Runs]] = {}
    for name in args.systems:
        results[name] = {}
        for method in methods:
            if args.quick and method == "gpr" and name == "plates3d":
                log("  plates3d  gpr: skipped in --quick")
                continue
            horizon = horizons[name]
            if method == "gpr":
                horizon = max(REFERENCE_SETTINGS[name][0], min(horizon, args.gpr_horizon))
            results[name][method] = measure(name, method, seeds, horizon, log)
    print("\n".join(table(results, horizons)))
    if args.png is not None:
        figure(results, horizons, args.png / "fig3_8.png")
        print(f"\nwrote {args.png / 'fig3_8.png'}")
    print(f"\nTotal run time {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
