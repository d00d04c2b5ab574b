"""Chapter 4 reproduced: noisy boundaries (Figures 4.4, 4.6), Table 4.2, section 4.3.5.

Three parts, each printed as a table:

1. Noise (sections 4.2.1-4.2.2): Sobol against the NNDV search on Plates2D, 1000 samples
   in batches of 100, as the noise grows. Figure 4.4: a fuzzy boundary, the wrong mode
   (the one across the nearest boundary) drawn with the paper's probability
   ``0.5 exp(-d^2 / (2 sigma^2))``, d the distance to the noise-free boundary, sigma up
   to 0.4. Figure 4.6: a global error, every label replaced by another mode with
   probability gamma up to 20 % (:class:`rapt.testfunctions.noise.GlobalNoise`).
   Precision and coverage are measured against the noise-free boundary, with the band
   half-width the paper states for these figures (0.1) and with chapter 3's (0.01).
   ``--png DIR`` draws fig4_4.png and fig4_6.png: the curves above, scatterplots of the
   NNDV search at a few noise levels below.
2. Table 4.2: the dithering study of the field plan's pairs, read from a plan.json
   (default the bundled ``field_plans/range2017/plan.json``): per pair the original and
   refined pair distance and boundary type with its score-tree index, and per scenario
   the distance to the nearest run of another mode and to the nearest sub-boundary the
   dithers found, with that sub-boundary's element and index.
3. Section 4.3.5 on UUV data: a Sobol study of ``examples/range2017.toml``
   (sim.uuv.simulate, deterministic), then the sub-boundary tree (Algorithm 3, all 70
   score elements, 4 levels) against the old method (Algorithm 2: modes from k score
   elements at once, pairs between every two modes) on progressively deeper levels of
   the score tree, and the tree's time as the study grows (Figure 4.19; fig4_19.png).

Run:  python benchmarks/reproduce_noise.py [--quick] [--png DIR] [--seeds N] [--fuzzy-model jitter]
                                           [--skip-noise] [--skip-table42] [--skip-subclustering]
                                           [--plan PATH] [--sizes N ...]

``--fuzzy-model jitter`` runs Figure 4.4 only, with RAPT's own fuzzy boundary (labels
at a Gaussian-jittered input) in place of the paper's formula (fig4_4_jitter.png).
``--quick``: one seed and 5 noise levels per figure, a 3,000-run UUV study.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import qmc

import rapt
from rapt.boundaries import mutual_pairs
from rapt.metrics import boundary_coverage, boundary_precision
from rapt.modes import performance_modes
from rapt.testfunctions.base import SyntheticSystem
from rapt.testfunctions.noise import FuzzyBoundary, GlobalNoise
from rapt.testfunctions.shapes import Plates2D

ROOT = Path(__file__).resolve().parents[1]
BUDGET, BATCH = 1000, 100
D_EPS = (0.1, 0.01)  # the paper's band for Figures 4.4/4.6, and chapter 3's
SIGMAS: tuple[float, ...] = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4)
GAMMAS: tuple[float, ...] = (0.0, 0.025, 0.05, 0.075, 0.1, 0.15, 0.2)
SCATTER = {"fuzzy": (0.05, 0.1, 0.2, 0.4), "global": (0.025, 0.05, 0.1, 0.2)}


class PaperFuzzy(SyntheticSystem):
    """Plates2D with the paper's fuzzy boundary (section 4.2.1).

    A sample at distance d from the nearest plate outline gets the mode across that
    outline with probability ``0.5 exp(-d^2 / (2 sigma^2))`` (the text prints ``2 sigma``;
    its Figure 4.3 shades ``sigma`` as a distance, so sigma is read as a standard
    deviation). ``boundary_distance`` is the noise-free one. Deterministic given ``seed``
    and the call order.
    """

    def __init__(self, sigma: float, seed: int = 0):
        self.base = Plates2D()
        self.sigma = float(sigma)
        self.rng = np.random.default_rng(seed)
        self.name = f"plates2d-paperfuzzy{sigma:g}"
        self.dim, self.n_outputs = 2, 1
        self.output_types, self.n_classes = self.base.output_types, self.base.n_classes
        self.active_dims = self.base.active_dims

    def _evaluate(self, X):
        Y = self.base(X)
        sd = np.abs(self.base.signed_distances(X))
        k = np.argmin(sd, axis=1)
        d = sd[np.arange(len(X)), k]
        p = 0.5 * np.exp(-(d**2) / (2 * self.sigma**2)) if self.sigma > 0 else np.zeros(len(X))
        flip = self.rng.random(len(X)) < p
        across = np.where(Y[:, 0] == k + 1, 0.0, k + 1.0)
        Y[flip, 0] = across[flip]
        return Y

    def _distance(self, X):
        return self.base.boundary_distance(X)


def noisy_system(kind: str, level: float, seed: int, model: str = "paper") -> SyntheticSystem:
    """The noisy Plates2D of Figure 4.4 (``fuzzy``, level sigma) or 4.6 (``global``, level gamma).

    ``model="jitter"`` takes RAPT's own fuzzy boundary (labels at a Gaussian-jittered
    input, :class:`rapt.testfunctions.noise.FuzzyBoundary`) in place of the paper's.
    """
    if kind == "global":
        return GlobalNoise(Plates2D(), level, seed=seed)
    return PaperFuzzy(level, seed) if model == "paper" else FuzzyBoundary(Plates2D(), level, seed=seed)


def noise_sweep(kind: str, levels, seeds: int, model: str = "paper") -> tuple[dict, dict]:
    """Precision and coverage (mean over seeds) per method, level and band; NNDV studies of seed 0."""
    truth = Plates2D()
    res: dict = {}
    shown: dict = {}
    for method in ("sobol", "nndv"):
        for level in levels:
            runs = []
            for seed in range(seeds):
                system = noisy_system(kind, level, seed, model)
                study = rapt.search(
                    system, [(0.0, 1.0)] * 2, BUDGET, method=method, batch_size=BATCH, seed=seed,
                    output_types=["categorical"],
                )  # fmt: skip
                runs.append(
                    [
                        v
                        for d in D_EPS
                        for v in (boundary_precision(truth, study.X, d)[0], boundary_coverage(truth, study.X, d)[0])
                    ]
                )
                if method == "nndv" and seed == 0:
                    shown[level] = (study.X, study.Y[:, 0])
            res[method, level] = np.mean(runs, axis=0)
    return res, shown


def print_noise(kind: str, levels, res: dict, seeds: int, model: str = "paper") -> None:
    name = "sigma" if kind == "fuzzy" else "gamma"
    fig = f"4.4, fuzzy boundary ({model} model)" if kind == "fuzzy" else "4.6, global error"
    print(f"\nFigure {fig}: Plates2D, {BUDGET} samples, mean of {seeds} seed(s); P = precision, C = coverage")
    head = "  ".join(f"{m} P/C @{d:g}" for d in D_EPS for m in ("Sobol", "NNDV"))
    print(f"{name:>6}  {head}")
    for level in levels:
        cells = []
        for k in range(len(D_EPS)):
            for m in ("sobol", "nndv"):
                p, c = res[m, level][2 * k : 2 * k + 2]
                cells.append(f"{p:>6.1%} / {c:>6.1%}".rjust(len(f"{m} P/C @{D_EPS[k]:g}")))
        print(f"{level:>6g}  " + "  ".join(cells), flush=True)


def plot_noise(kind: str, levels, res: dict, shown: dict, path: Path) -> None:
    """Curves against the noise level above, NNDV scatterplots below (the paper's layout)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    levels_shown = SCATTER[kind]
    fig = plt.figure(figsize=(13, 7))
    grid = fig.add_gridspec(2, len(levels_shown), height_ratios=[1.1, 1])
    label = "boundary width σ" if kind == "fuzzy" else "global error rate γ"
    for col, metric in enumerate(("precision", "coverage")):
        ax = fig.add_subplot(grid[0, 2 * col : 2 * col + 2])
        for k, d in enumerate(D_EPS):
            for m, colour in (("sobol", "tab:blue"), ("nndv", "tab:red")):
                y = [res[m, lv][2 * k + col] for lv in levels]
                ax.plot(levels, y, "-o" if k == 0 else "--s", color=colour, ms=4, label=f"{m.upper()}, band {d:g}")
        ax.set_xlabel(label)
        ax.set_ylabel(metric)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    xx, yy = np.meshgrid(np.linspace(0, 1, 400), np.linspace(0, 1, 400))
    dist = Plates2D().boundary_distance(np.column_stack([xx.ravel(), yy.ravel()]))[:, 0].reshape(xx.shape)
    for col, lv in enumerate(levels_shown):
        ax = fig.add_subplot(grid[1, col])
        if kind == "fuzzy":
            ax.contourf(xx, yy, dist, levels=[0, lv], colors=["0.85"])
        ax.contour(xx, yy, dist, levels=[1e-3], colors="red", linewidths=0.8)
        X, y = shown[lv]
        ax.scatter(X[:, 0], X[:, 1], c=y, cmap="tab10", vmin=0, vmax=9, s=4)
        ax.set_title(f"NNDV, {'σ' if kind == 'fuzzy' else 'γ'} = {lv:g}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_aspect("equal")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


# ---------------------------------------------------------------------------- Table 4.2
#: The dissertation's Table 4.2: pair, original distance and type, then per scenario the
#: distance to the boundary the dithering found and its type (score-tree index).
PAPER_42 = (
    (1, 0.259, "Collision (11)", ((65315, 0.101, "Collision (11)"), (71349, 0.256, "Collision (11)"))),
    (2, 0.340, "Waypoint (15)", ((55433, 0.050, "Mission Return (21)"), (53451, 0.042, "Mission Return (21)"))),
    (3, 0.247, "Mission Abort (26)", ((21063, 0.050, "Mission Abort (26)"), (127386, 0.042, "Mission Abort (27)"))),
    (4, 0.2526, "Mission Abort (35)", ((21063, 0.052, "Mission Abort (35)"), (127386, 0.073, "Mission Abort (35)"))),
    (5, 0.2950, "Transmission (8)", ((112122, 0.054, "Transmission (8)"), (145263, 0.073, "Transmission (8)"))),
)


def _typed(elements, index: dict) -> str:
    return ", ".join(f"{e} ({index[e]})" if e in index else e for e in elements)


def table42(plan_path: Path) -> list[dict]:
    """Table 4.2's columns from a plan's pairs and dithering results; returns the rows printed."""
    from sim.uuv import load_mission
    from sim.uuv.metrics import metric_names

    plan = json.loads(plan_path.read_text())
    source = Path(plan["mission"].get("file") or "examples/range2017.toml")
    mission_file = source if source.is_absolute() else ROOT / source
    index = {n: i for i, n in enumerate(metric_names(load_mission(mission_file)))}
    scen = {s["id"]: s for s in plan["scenarios"]}
    dith = plan["study"]["dithering"]
    print(
        f"\nTable 4.2 from {plan_path.relative_to(ROOT) if plan_path.is_relative_to(ROOT) else plan_path}: "
        f"{dith['runs_per_scenario']} dithers per scenario, noise {dith['expected']}; distances in the unit cube "
        f"({len(plan['scenarios'][0]['u'])}-D); index = score-tree column"
    )
    print(
        f"{'pair':>4} {'original':>8} {'refined':>7} {'boundary type':<34} {'scenario':<8} {'mode':>4} "
        f"{'p(shown)':>8} {'other mode':>10} {'nearest sub-boundary (index, relation)':<44} {'dist':>6}"
    )
    rows = []
    for pair in plan["pairs"]:
        original = (pair.get("refinement") or {}).get("start_distance", pair["distance"])
        for k, sid in enumerate(pair["scenarios"]):
            d = scen[sid]["dithering"]
            subs = d.get("sub_boundaries") or []
            sub = subs[0] if subs else None
            row = {
                "pair": pair["id"], "original": original, "refined": pair["distance"],
                "type": _typed(pair["elements"], index), "modes": pair["modes"], "scenario": sid,
                "mode": scen[sid]["predicted"]["mode"], "p": d.get("p_predicted"),
                "other_mode": d.get("nearest_other_mode"),
                "sub": None if sub is None else f"{sub['element']} ({index.get(sub['element'], '?')}, {sub['relation']})",
                "sub_dist": None if sub is None else sub["nearest"],
            }  # fmt: skip
            rows.append(row)
            lead = (
                f"{pair['id']:>4} {original:>8.3f} {pair['distance']:>7.3f} {row['type']:<34}"
                if k == 0
                else " " * 4 + " " * 18 + f" {'/'.join(pair['modes']):<34}"
            )
            om = "–" if row["other_mode"] is None else f"{row['other_mode']:.3f}"
            sd = "–" if sub is None else f"{sub['nearest']:.3f}"
            print(f"{lead} {sid:<8} {row['mode']:>4} {row['p']:>8.1%} {om:>10} {row['sub'] or 'none':<44} {sd:>6}")
    print("\nThe dissertation's Table 4.2 (13 parameters, 123k runs searched; 2,000 dithers per scenario):")
    for pid, dist, typ, sides in PAPER_42:
        for k, (sid, dd, dt) in enumerate(sides):
            lead = f"{pid:>4} {dist:>8.4g} {typ:<20}" if k == 0 else " " * 34
            print(f"{lead} {sid:>7} {dd:>6.3f} {dt}")
    return rows


# ------------------------------------------------------------------------ section 4.3.5
def uuv_study(n: int, seed: int = 0):
    """A Sobol study of range2017 (``n`` scenarios, deterministic runs).

    Returns the valid rows' states, scores and Sobol indices, the mission and the score types.
    """
    import sim.uuv

    mission = sim.uuv.load_mission(ROOT / "examples" / "range2017.toml")
    X = qmc.Sobol(mission.dim, seed=seed).random_base2(int(np.ceil(np.log2(n))))[:n]
    parts = [sim.uuv.simulate(mission, X[s : s + 4096]) for s in range(0, n, 4096)]
    valid = np.concatenate([p.valid for p in parts])
    scores = np.concatenate([p.scores for p in parts])
    return X[valid], scores[valid], np.flatnonzero(valid), mission, parts[0].output_types


def _levels(tree: dict) -> list[list[int]]:
    """Score columns of each level of a score-tree mapping, root first."""
    out: list[list[int]] = []
    todo = [(tree, 0)]
    while todo:
        node, depth = todo.pop(0)
        while len(out) <= depth:
            out.append([])
        out[depth] += list(node["indices"])
        todo += [(c, depth + 1) for c in node["children"]]
    return out


def old_method(X: np.ndarray, Y: np.ndarray, types) -> tuple[float, int, int]:
    """Algorithm 2 on all the given score columns at once: seconds, modes, pairs."""
    t0 = time.perf_counter()
    labels = performance_modes(Y, types)
    i, _, _ = mutual_pairs(X, labels)
    return time.perf_counter() - t0, int(labels.max()) + 1, int(i.size)


def subclustering(sizes: list[int], old_max_n: int, png: Path | None = None) -> None:
    """Figure 4.19 on UUV data: the tree against Algorithm 2 on deeper levels, and against study size."""
    n_big = max(sizes)
    t0 = time.perf_counter()
    X, Y, rows, mission, types = uuv_study(n_big)
    print(
        f"\nSection 4.3.5 on UUV data: Sobol study of range2017, {n_big:,} scenarios, {len(X):,} valid "
        f"({time.perf_counter() - t0:.0f} s to simulate); {Y.shape[1]} score elements",
        flush=True,
    )
    levels = _levels(mission.score_tree)
    print(f"score tree: {len(levels)} levels, {'/'.join(str(len(lv)) for lv in levels)} elements per level")
    n_old = min(old_max_n, len(X))
    print(f"\n(a) {n_old:,} valid runs: Algorithm 2 on levels 0..L at once against the sub-boundary tree")
    print(f"{'method':<40} {'elements':>8} {'time (s)':>9} {'modes/clusters':>17} {'pairs':>8}")
    bars: list[tuple[str, float]] = []
    for depth in range(len(levels)):
        cols = [c for lv in levels[: depth + 1] for c in lv]
        t, modes, pairs = old_method(X[:n_old], Y[:n_old, cols], [types[c] for c in cols])
        bars.append((f"Alg. 2\n{len(cols)} scores", t))
        label = f"Algorithm 2, levels 0..{depth}"
        print(f"{label:<40} {len(cols):>8} {t:>9.2f} {modes:>17,} {pairs:>8,}", flush=True)
    bars.append((f"tree\n{Y.shape[1]} scores", tree_row(X[:n_old], Y[:n_old], mission, types, "sub-boundary tree")))
    cheap = [c for lv in levels[:2] for c in lv]
    print(f"\n(b) as the study grows: the tree (all {Y.shape[1]} elements), Algorithm 2 on levels 0..1 ({len(cheap)})")
    lines: list[tuple[int, float, float]] = []
    for n in sorted(sizes):
        m = int(np.sum(rows < n))
        t_tree = tree_row(X[:m], Y[:m], mission, types, f"tree, first {n:,} scenarios ({m:,} valid)")
        t, modes, pairs = old_method(X[:m], Y[:m, cheap], [types[c] for c in cheap])
        print(f"{'Algorithm 2, levels 0..1':<40} {len(cheap):>8} {t:>9.2f} {modes:>17,} {pairs:>8,}", flush=True)
        lines.append((m, t_tree, t))
    if png is not None:
        plot_4_19(bars, lines, n_old, png / "fig4_19.png")


def plot_4_19(bars: list[tuple[str, float]], lines: list[tuple[int, float, float]], n_old: int, path: Path) -> None:
    """Figure 4.19's layout: time per method at one size (left), time against size (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5))
    left.bar(range(len(bars)), [t for _, t in bars], color=["tab:blue"] * (len(bars) - 1) + ["tab:red"])
    left.set_xticks(range(len(bars)), [lab for lab, _ in bars], fontsize=8)
    left.set_ylabel("seconds")
    left.set_title(f"{n_old:,} valid UUV runs")
    n = [r[0] for r in lines]
    right.plot(n, [r[1] for r in lines], "-o", color="tab:red", label="sub-boundary tree, all scores")
    right.plot(n, [r[2] for r in lines], "--s", color="tab:blue", label="Algorithm 2, levels 0..1")
    right.set_xlabel("valid runs")
    right.set_ylabel("seconds")
    right.legend()
    right.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def tree_row(X, Y, mission, types, label: str) -> float:
    """Time the sub-boundary tree; count its clusters per level, pairs and boundary types.

    A boundary type is a level and the discrete score elements of that level that differ
    across a pair (as ``rapt-plan generate`` names them); pairs split only by continuous
    elements share one type per level. Discrete outcomes: distinct combinations of all
    discrete score elements among the runs (sub-cluster types without continuous leaves).
    """
    t0 = time.perf_counter()
    tree = rapt.subboundary_tree(X, Y, mission.score_tree, output_types=types)
    t = time.perf_counter() - t0
    i, j, _, lv = tree.pairs()
    kinds = 0
    for level, cols in enumerate(tree.levels):
        disc = [c for c in cols if types[c] != "continuous"]
        at = lv == level
        if at.any():
            diff = Y[i[at]][:, disc] != Y[j[at]][:, disc]
            kinds += len(np.unique(diff, axis=0)) if disc else 1
    clusters = "/".join(str(tree.n_clusters(k)) for k in range(len(tree.levels)))
    disc_all = [c for c, t in enumerate(types) if t != "continuous"]
    combos = len(np.unique(Y[:, disc_all], axis=0))
    tm = "/".join(f"{tree.timings[k]:.1f}" for k in ("split", "graph", "pairs"))
    print(
        f"{label:<40} {Y.shape[1]:>8} {t:>9.2f} {clusters:>17} {i.size:>8,}  {kinds:,} types; {combos:,} discrete outcomes; split/graph/pairs {tm} s",
        flush=True,
    )
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 seed, 5 levels per figure, a 3,000-run UUV study")
    ap.add_argument("--png", type=Path, default=None, help="directory for fig4_4.png and fig4_6.png")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per noise level (default 3; --quick 1)")
    ap.add_argument("--plan", type=Path, default=ROOT / "field_plans" / "range2017" / "plan.json")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="UUV study sizes (default 10000 30000 100000)")
    ap.add_argument("--old-max", type=int, default=None, help="runs given to Algorithm 2 (default 5000; --quick 3000)")
    ap.add_argument(
        "--fuzzy-model", choices=("paper", "jitter"), default="paper", help="Figure 4.4's noise (jitter: RAPT's own)"
    )
    ap.add_argument("--skip-noise", action="store_true")
    ap.add_argument("--skip-table42", action="store_true")
    ap.add_argument("--skip-subclustering", action="store_true")
    args = ap.parse_args()
    seeds = args.seeds or (1 if args.quick else 3)
    if not args.skip_noise:
        for kind, levels in (("fuzzy", SIGMAS), ("global", GAMMAS)):
            if args.quick:
                levels = tuple(sorted({0.0, *SCATTER[kind]}))
            if kind == "global" and args.fuzzy_model == "jitter":
                continue
            res, shown = noise_sweep(kind, levels, seeds, args.fuzzy_model)
            print_noise(kind, levels, res, seeds, args.fuzzy_model)
            if args.png is not None:
                name = (
                    "fig4_6.png"
                    if kind == "global"
                    else f"fig4_4{'_jitter' if args.fuzzy_model == 'jitter' else ''}.png"
                )
                plot_noise(kind, levels, res, shown, args.png / name)
    if not args.skip_table42:
        table42(args.plan.resolve())
    if not args.skip_subclustering:
        sizes = args.sizes or ([1_000, 3_000] if args.quick else [10_000, 30_000, 100_000])
        subclustering(sizes, args.old_max or (3_000 if args.quick else 5_000), args.png)


if __name__ == "__main__":
    main()
