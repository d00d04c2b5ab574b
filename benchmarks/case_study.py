"""Section 3.7's UUV case study: a million runs of the 18-parameter mission, S-NDV against Sobol.

What it measures (Figures 3.12 and 3.13 of Mullins 2018)
--------------------------------------------------------
``examples/uuv18.toml`` (start time, transmission window and area, no-go area, three minor
obstacles, two barriers, mission-area priority order) is searched twice with the same
budget, in batches of 10,000 as the paper submitted them: by a Sobol design and by S-NDV
steered on mission and safety success, as ``rapt-plan generate`` steers it. Both studies
run on a process pool (one worker per core) and are stored in SQLite, so a study killed
halfway resumes where it stopped. Then, for each:

* Figure 3.12 (a): the share of valid runs in each performance mode (TF, SS, MS, TS);
* Figure 3.12 (b), (c): the share of boundary pairs of each boundary type, and S-NDV's
  change against Sobol;
* Figure 3.13 (a): the histogram of boundary-pair distances in the unit space;
* Figure 3.13 (c): each boundary type's mean pair distance, after the paper's threshold
  (D_eps at the 80th percentile of the type's pair distances).

Boundary pairs are mutual nearest neighbours of different modes within each run's 12
nearest runs (:func:`rapt.boundaries.graph_mutual_pairs`; the graph is faiss HNSW beyond
20,000 runs, re-measured exactly): an exact all-pairs search of 850,000 runs in 20
dimensions would take hours, and pairs longer than a run's 12th neighbour are not local
evidence of a boundary.

Run:  python benchmarks/case_study.py [--runs 1000000] [--batch 10000] [--store DIR] [--png DIR] [--quick]

``--quick`` runs 20,000 runs per method in batches of 2,000. A study in ``--store`` is
resumed, not rerun; its time is then the remaining part's only.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np

import rapt
import sim.uuv
from planner.plan.generate import ROOT_COLUMNS, SEARCH_REFERENCE, MissionScores
from planner.plan.mission_search import ROOT_OUTPUT_TYPES
from rapt.boundaries import exact_order, graph_mutual_pairs, knn_graph
from sim.uuv.scoring import MODE_NAMES

MISSION = Path(__file__).resolve().parents[1] / "examples" / "uuv18.toml"
METHODS = ("sobol", "s-ndv")
#: The paper's figures (section 3.7.3), read from its text.
PAPER = {
    "valid": {"sobol": 850_000, "s-ndv": 883_000},
    "common boundary change": "SS/TF -20 %; every other boundary +50 % or more",
    "distance change": "mean distance about -10 %; each boundary 4-8 % closer",
}


def run_study(method: str, mission, runs: int, batch: int, store: Path, pool, workers: int) -> tuple[rapt.Study, float]:
    """One search of the mission, resumed from ``store`` if it exists; returns (study, seconds).

    Each batch is split into one chunk per worker: a chunk's last long runs step a few
    vehicles at a time, so fewer, larger chunks waste less.
    """
    options = {"max_reference": SEARCH_REFERENCE} if method == "s-ndv" else {}
    started = time.perf_counter()
    last = [started]

    def progress(done: int, total: int) -> None:
        now = time.perf_counter()
        if now - last[0] > 60 or done == total:
            print(f"   {method}: {done:,}/{total:,} runs, {now - started:.0f} s", flush=True)
            last[0] = now

    study = rapt.search(
        MissionScores(mission),
        mission.space,
        runs,
        method=method,
        batch_size=batch,
        seed=0,
        store=store,
        executor=pool,
        chunk_size=-(-batch // workers),
        output_types=ROOT_OUTPUT_TYPES,
        steer=list(ROOT_COLUMNS),
        sampler_options=options,
        n_initial=batch,
        progress=progress,
    )
    return study, time.perf_counter() - started


def analyse(study: rapt.Study) -> dict:
    """Modes, boundary pairs per type and their distances (Figures 3.12 and 3.13)."""
    X = study.X
    modes = (2 * study.Y[:, 0] + study.Y[:, 1]).astype(int)
    started = time.perf_counter()
    dist, idx = exact_order(X, knn_graph(X, 12)[1])
    i, j, d = graph_mutual_pairs(dist, idx, modes)
    types: dict[str, np.ndarray] = {}
    for a in range(4):
        for b in range(a + 1, 4):
            sel = (modes[i] == a) & (modes[j] == b)
            if sel.any():
                types[f"{MODE_NAMES[b]}/{MODE_NAMES[a]}"] = d[sel]
    return {
        "runs": study.n_evaluated,
        "valid": X.shape[0],
        "modes": np.bincount(modes, minlength=4) / max(modes.size, 1),
        "pairs": d,
        "types": types,
        "seconds": time.perf_counter() - started,
    }


def thresholded_mean(d: np.ndarray, quantile: float = 0.8) -> float:
    """Mean pair distance after the paper's D_eps (the type's 80th percentile)."""
    return float(d[d <= np.quantile(d, quantile)].mean())


def report(results: dict[str, dict], seconds: dict[str, float]) -> None:
    sob, snd = results["sobol"], results["s-ndv"]
    print("\nFigure 3.12 (a): share of valid runs per performance mode")
    print(f"{'mode':>5} {'Sobol':>8} {'S-NDV':>8} {'change':>8}")
    for k, name in enumerate(MODE_NAMES):
        a, b = sob["modes"][k], snd["modes"][k]
        print(f"{name:>5} {a:>8.1%} {b:>8.1%} {(b / a - 1) if a else float('nan'):>+8.0%}")
    print("\nFigure 3.12 (b), (c) and 3.13 (c): boundary pairs per type")
    print(
        f"{'boundary':>9} {'Sobol pairs':>12} {'share':>6} {'S-NDV pairs':>12} {'share':>6} {'change':>7} "
        f"{'mean d Sobol':>12} {'mean d S-NDV':>12} {'change':>7}"
    )
    ns, nn = sob["pairs"].size, snd["pairs"].size
    for t in sorted(set(sob["types"]) | set(snd["types"]), key=lambda t: -sob["types"].get(t, np.empty(0)).size):
        a, b = sob["types"].get(t, np.empty(0)), snd["types"].get(t, np.empty(0))
        sa, sb = a.size / max(ns, 1), b.size / max(nn, 1)
        da = thresholded_mean(a) if a.size else float("nan")
        db = thresholded_mean(b) if b.size else float("nan")
        print(
            f"{t:>9} {a.size:>12,} {sa:>6.1%} {b.size:>12,} {sb:>6.1%} {(sb / sa - 1) if sa else float('nan'):>+7.0%} "
            f"{da:>12.4f} {db:>12.4f} {db / da - 1:>+7.1%}"
        )
    ma, mb = sob["pairs"].mean(), snd["pairs"].mean()
    print(f"\nFigure 3.13 (a): mean boundary-pair distance Sobol {ma:.4f}, S-NDV {mb:.4f} ({mb / ma - 1:+.1%})")
    print("\nthe paper:", "; ".join(f"{k}: {v}" for k, v in PAPER.items()))
    print("\nruns, valid runs and time")
    for m in METHODS:
        r = results[m]
        print(
            f"   {m:>6}: {r['runs']:,} runs, {r['valid']:,} valid; search {seconds[m]:.0f} s "
            f"({r['runs'] / max(seconds[m], 1e-9):,.0f} runs/s), analysis {r['seconds']:.0f} s"
        )


def draw(results: dict[str, dict], out: Path) -> None:
    """Figures 3.12 and 3.13 as PNGs in ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    colours = {"sobol": "tab:gray", "s-ndv": "tab:blue"}
    types = sorted(results["sobol"]["types"], key=lambda t: -results["sobol"]["types"][t].size)
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    w = 0.4
    for k, m in enumerate(METHODS):
        r = results[m]
        ax[0].bar(np.arange(4) + (k - 0.5) * w, r["modes"], w, label=m, color=colours[m])
        share = [r["types"].get(t, np.empty(0)).size / max(r["pairs"].size, 1) for t in types]
        ax[1].bar(np.arange(len(types)) + (k - 0.5) * w, share, w, label=m, color=colours[m])
    base = [results["sobol"]["types"][t].size / results["sobol"]["pairs"].size for t in types]
    new = [results["s-ndv"]["types"].get(t, np.empty(0)).size / results["s-ndv"]["pairs"].size for t in types]
    ax[2].bar(np.arange(len(types)), [100 * (b / a - 1) for a, b in zip(base, new)], color=colours["s-ndv"])
    ax[0].set(xticks=range(4), xticklabels=MODE_NAMES, title="(a) performance modes", ylabel="share of valid runs")
    ax[1].set(xticks=range(len(types)), xticklabels=types, title="(b) boundary types", ylabel="share of pairs")
    ax[2].set(xticks=range(len(types)), xticklabels=types, title="(c) S-NDV against Sobol", ylabel="change (%)")
    ax[0].legend()
    fig.tight_layout()
    fig.savefig(out / "fig3_12.png", dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    top = np.quantile(results["sobol"]["pairs"], 0.99)
    for m in METHODS:
        ax[0].hist(results[m]["pairs"], bins=60, range=(0, top), histtype="step", label=m, color=colours[m])
    means = {m: [thresholded_mean(results[m]["types"][t]) for t in types] for m in METHODS}
    for k, m in enumerate(METHODS):
        ax[1].bar(np.arange(len(types)) + (k - 0.5) * w, means[m], w, label=m, color=colours[m])
    ax[0].set(title="(a) boundary-pair distances", xlabel="distance (unit space)", ylabel="pairs")
    ax[1].set(xticks=range(len(types)), xticklabels=types, title="(c) mean distance after D_eps", ylabel="distance")
    ax[0].legend()
    fig.tight_layout()
    fig.savefig(out / "fig3_13.png", dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=None, help="runs per method (default 1,000,000; --quick: 20,000)")
    ap.add_argument("--batch", type=int, default=None, help="runs per batch (default 10,000; --quick: 2,000)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2, help="simulation processes")
    ap.add_argument("--store", type=Path, default=Path("case_study"), help="directory of the two study stores")
    ap.add_argument("--png", type=Path, default=None, help="write fig3_12.png and fig3_13.png here")
    ap.add_argument("--quick", action="store_true", help="20,000 runs per method")
    args = ap.parse_args()
    runs = args.runs or (20_000 if args.quick else 1_000_000)
    batch = args.batch or (2_000 if args.quick else 10_000)
    mission = sim.uuv.load_mission(MISSION)
    args.store.mkdir(parents=True, exist_ok=True)
    print(
        f"{mission.name}: {mission.dim} parameters, {runs:,} runs per method in batches of {batch:,}, "
        f"{args.workers} processes"
    )
    results, seconds = {}, {}
    context = multiprocessing.get_context("forkserver")
    with cf.ProcessPoolExecutor(args.workers, mp_context=context) as pool:
        for m in METHODS:
            study, seconds[m] = run_study(
                m, mission, runs, batch, args.store / f"uuv18-{m}-{runs}.db", pool, args.workers
            )
            results[m] = analyse(study)
    report(results, seconds)
    if args.png is not None:
        draw(results, args.png)
        print(f"\nfigures written to {args.png}/fig3_12.png and fig3_13.png")


if __name__ == "__main__":
    main()
