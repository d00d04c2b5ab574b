"""Boundary identification: correctness, noise, and the cost of a sub-boundary tree.

Three parts, each printed as a table:

1. Correctness on the hierarchical system of section 4.3.2 (``Hierarchical2D``: 2
   inputs, 12 score elements, 3 levels) after a 4000-sample S-NDV search: per level,
   the share of true sub-boundary types recovered (a pair of that type shorter than
   0.05) and the share of reported pairs lying on a true boundary.
2. Noise (section 4.2): Plates2D with fuzzy boundaries (sigma) and with a global error
   rate (gamma): how many boundary pairs lie on a true boundary, and how well the DBSCAN
   noise flag separates false pairs from true ones (share of false pairs flagged, share
   of true pairs kept).
3. Cost: the full sub-boundary tree of ``HierarchicalND`` (18 inputs, 66 leaves, 4
   levels) at growing sample counts, peak memory, the recall of the neighbour graph
   (share of the exact 12 nearest neighbours found, 10^4 sampled rows, brute force), and
   — at the smallest size — the old all-leaves-at-once method (modes from all 66
   leaves, pairs between every two modes) for comparison.
4. Analysis ready when the search ends: the neighbour graph grown batch by batch
   (:class:`rapt.neighbours.GrowingGraph`, as ``rapt.search(neighbour_graph=12)`` grows it)
   on 10^6 uniform samples and on an S-NDV study of ``HierarchicalND``: the growth cost
   per batch and in total, then the sub-boundary tree with the grown graph (the analysis
   left after the last batch) against today's from scratch, with both graphs' recall.

Run:  python benchmarks/boundaries.py [--sizes 10000 100000 1000000] [--skip-noise] [--quick]
                                      [--grow N] [--grow-sndv N] [--skip-cost]

``--quick`` prints the same three tables from a small run (about a minute on 2 cores):
2000 samples for part 1, 1000 per noise level for part 2, and 3,000 and 30,000 samples
(one exact, one HNSW graph) for part 3, 30,000 uniform and 10,000 S-NDV samples for part 4.

The S-NDV study of part 4 runs as ``rapt-plan generate`` runs its search: steered on the
root scores, a 20 % space-filling start, ``max_reference`` 10,000, batches of 5,000.
Its search alone takes about 10 s per batch here (the sampler, not the graph), so
``--grow-sndv`` defaults to 10^5 samples; 10^6 takes about 40 minutes.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

import rapt
from rapt.boundaries import EXACT_GRAPH_MAX_SAMPLES, boundary_pairs, mutual_pairs
from rapt.metrics import subboundary_recovery
from rapt.modes import performance_modes
from rapt.testfunctions.hierarchical import Hierarchical2D, HierarchicalND
from rapt.testfunctions.noise import FuzzyBoundary, GlobalNoise
from rapt.testfunctions.shapes import Plates2D


def correctness(n: int = 4000) -> None:
    h = Hierarchical2D()
    study = rapt.search(h, [(0, 1)] * 2, n, method="s-ndv", seed=0, output_types=("categorical",) * 12)
    tree = rapt.subboundary_tree(study.X, study.Y, h.score_tree)
    print(f"1. Hierarchical2D (12 elements, 3 levels), {n} S-NDV samples")
    print(f"{'level':>5} {'clusters':>8} {'true types':>10} {'recovered':>9} {'pairs':>6} {'on a true boundary':>19}")
    for row in subboundary_recovery(h, tree, grid=512, tol=0.05):
        print(
            f"{row['level']:>5} {tree.n_clusters(row['level']):>8} {row['true_types']:>10} "
            f"{row['recovered_fraction']:>9.0%} {row['pairs']:>6} {row['on_boundary_fraction']:>19.1%}"
        )


def noise(n: int = 3000, tol: float = 0.03) -> None:
    truth = Plates2D()
    print(
        f"\n2. Noise on Plates2D, {n} S-NDV samples; a pair is true when both ends lie within {tol} of a true "
        "boundary (and, with global noise, both carry their noise-free label)"
    )
    print(f"{'system':>16} {'pairs':>6} {'true':>6} {'false flagged':>13} {'true kept':>9}")
    for label, system in (
        [("clean", Plates2D())]
        + [(f"fuzzy σ={s}", FuzzyBoundary(Plates2D(), s, seed=1)) for s in (0.01, 0.03, 0.05)]
        + [(f"global γ={g}", GlobalNoise(Plates2D(), g, seed=1)) for g in (0.02, 0.05, 0.1, 0.2)]
    ):
        study = rapt.search(system, [(0, 1)] * 2, n, method="s-ndv", seed=0, output_types=("categorical",))
        bp = boundary_pairs(study.X, study.Y, cluster_eps=0.05, min_samples=5)
        d = truth.boundary_distance(study.X)[:, 0]
        near = (d[bp.i] < tol) & (d[bp.j] < tol)
        if isinstance(system, GlobalNoise):  # a flipped label far from home is an outlier, not a boundary
            clean = truth(study.X)[:, 0] == study.Y[:, 0]
            true = near & clean[bp.i] & clean[bp.j]
        else:  # a fuzzy boundary's mixed labels are the boundary region itself
            true = near
        flagged_false = bp.likely_noise[~true].mean() if np.any(~true) else float("nan")
        kept_true = (~bp.likely_noise[true]).mean() if np.any(true) else float("nan")
        print(f"{label:>16} {len(bp):>6} {true.mean():>6.1%} {flagged_false:>13.1%} {kept_true:>9.1%}")


def graph_recall(X: np.ndarray, neighbours: np.ndarray, n_queries: int = 10_000, seed: int = 0) -> float:
    """Share of the exact k nearest neighbours found by the graph, on ``n_queries`` sampled rows.

    Exact neighbours by brute force (faiss ``IndexFlatL2``) against all samples.
    """
    import faiss

    n, k = neighbours.shape
    q = np.random.default_rng(seed).choice(n, min(n_queries, n), replace=False)
    Xf = np.ascontiguousarray(X, dtype=np.float32)
    flat = faiss.IndexFlatL2(Xf.shape[1])
    flat.add(Xf)
    _, exact = flat.search(Xf[q], k + 1)
    hits = [len(set(a.tolist()) & (set(b.tolist()) - {int(r)})) for a, b, r in zip(neighbours[q], exact, q)]
    return float(np.sum(hits)) / (k * q.size)


def cost(sizes: list[int]) -> None:
    h = HierarchicalND()
    rng = np.random.default_rng(0)
    print(
        f"\n3. Sub-boundary tree of {h.name} ({h.dim} inputs, 66 leaves, 4 levels), uniform samples; "
        f"target at 10^6: <= 20 s, <= 4 GB"
    )
    print(
        f"{'samples':>9} {'graph':>6} {'tree (s)':>9} {'split':>6} {'k-graph':>8} {'pairs':>6} "
        f"{'clusters per level':>22} {'pairs found':>11} {'peak RSS (GB)':>13} {'graph recall':>12}"
    )
    for n in sizes:
        X = rng.random((n, h.dim))
        Y = h(X)
        t0 = time.perf_counter()
        tree = rapt.subboundary_tree(X, Y, h.score_tree)
        t = time.perf_counter() - t0
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        clusters = "/".join(str(tree.n_clusters(lv)) for lv in range(4))
        kind = "exact" if n <= EXACT_GRAPH_MAX_SAMPLES else "hnsw"
        tm = tree.timings
        # recall of the exact 12 nearest neighbours, 10^4 sampled rows (measured after the peak)
        recall = "100 %" if kind == "exact" else f"{graph_recall(X, tree.neighbours):.1%}"
        print(
            f"{n:>9,} {kind:>6} {t:>9.2f} {tm['split']:>6.2f} {tm['graph']:>8.2f} {tm['pairs']:>6.2f} "
            f"{clusters:>22} {tree.pairs()[0].size:>11,} {peak:>13.2f} {recall:>12}",
            flush=True,
        )
        del tree, X, Y
    n = min(sizes)
    X = rng.random((n, h.dim))
    Y = h(X)
    t0 = time.perf_counter()
    labels = performance_modes(Y[:, 30:], ["binary"] * 66)
    i, _, _ = mutual_pairs(X, labels)
    t = time.perf_counter() - t0
    print(f"All 66 leaves at once (Algorithm 2), {n:,} samples: {t:.2f} s ({labels.max() + 1} modes, {i.size:,} pairs)")


def analysis_ready(n_uniform: int, n_sndv: int, batch: int = 5000) -> None:
    """Part 4: grow the graph batch by batch, then the analysis with it vs the tree from scratch."""
    from rapt.neighbours import GrowingGraph

    h = HierarchicalND()
    print(
        f"\n4. Analysis ready when the search ends: {h.name} sub-boundary tree with the graph grown during the "
        f"search (batches of {batch:,}) vs built from scratch; target at 10^6: analysis <= 20 s"
    )
    print(
        f"{'data':>8} {'samples':>9} {'search (s)':>10} {'growth (s)':>10} {'per batch':>15} "
        f"{'analysis (s)':>12} {'from scratch (s)':>16} {'ratio':>6} {'recall grown':>12} {'from scratch':>12}"
    )
    for data, n in (("uniform", n_uniform), ("S-NDV", n_sndv)):
        t0 = time.perf_counter()
        if data == "uniform":
            X = np.random.default_rng(1).random((n, h.dim))
            Y = h(X)
            batches = [np.arange(s, min(s + batch, n)) for s in range(0, n, batch)]
        else:
            study = rapt.search(
                h,
                [(0, 1)] * h.dim,
                n,
                method="s-ndv",
                batch_size=batch,
                seed=0,
                steer=[0, 1],
                output_types=("binary", "binary"),
                sampler_options={"max_reference": 10_000},
                n_initial=int(0.2 * n),
            )
            X, Y = study.U, study.Y
            batches = [np.flatnonzero(study.batch == b) for b in np.unique(study.batch)]
        searched = time.perf_counter() - t0
        g = GrowingGraph(h.dim, 12)
        per_batch = []
        for rows in batches:  # the same work rapt.search(neighbour_graph=12) does after each batch
            t0 = time.perf_counter()
            g.add(X[rows])
            per_batch.append(time.perf_counter() - t0)
        grown = g.graph()
        t0 = time.perf_counter()
        fast = rapt.subboundary_tree(X, Y, h.score_tree, graph=grown)
        t_fast = time.perf_counter() - t0
        t0 = time.perf_counter()
        slow = rapt.subboundary_tree(X, Y, h.score_tree)
        t_slow = time.perf_counter() - t0
        same = np.array_equal(fast.assignment, slow.assignment)
        pb = f"{np.mean(per_batch):.2f}/{np.max(per_batch):.2f}"
        print(
            f"{data:>8} {n:>9,} {searched:>10.1f} {sum(per_batch):>10.1f} {pb:>15} {t_fast:>12.2f} {t_slow:>16.1f} "
            f"{t_slow / t_fast:>5.1f}x {graph_recall(X, grown[1]):>12.1%} {graph_recall(X, slow.neighbours):>12.1%}",
            flush=True,
        )
        print(
            f"{'':>8} pairs: {fast.pairs()[0].size:,} grown vs {slow.pairs()[0].size:,} from scratch; same clusters: "
            f"{same}; analysis split/order/pairs {fast.timings['split']:.2f}/{fast.timings['graph']:.2f}/"
            f"{fast.timings['pairs']:.2f} s",
            flush=True,
        )
        del fast, slow, grown, g, X, Y


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=None,
        help="samples for part 3 (default 10000 100000 1000000; --quick: 3000 30000)",
    )
    ap.add_argument("--skip-noise", action="store_true")
    ap.add_argument("--skip-cost", action="store_true", help="skip part 3")
    ap.add_argument("--grow", type=int, default=None, help="uniform samples for part 4 (default 10^6)")
    ap.add_argument("--grow-sndv", type=int, default=None, help="S-NDV samples for part 4 (default 10^5)")
    ap.add_argument("--quick", action="store_true", help="the same tables from a small run (about a minute)")
    args = ap.parse_args()
    sizes = args.sizes or ([3_000, 30_000] if args.quick else [10_000, 100_000, 1_000_000])
    correctness(2000 if args.quick else 4000)
    if not args.skip_noise:
        noise(1000 if args.quick else 3000)
    if not args.skip_cost:
        cost(sorted(sizes))
    analysis_ready(
        args.grow or (30_000 if args.quick else 1_000_000),
        args.grow_sndv or (10_000 if args.quick else 100_000),
        1_000 if args.quick else 5_000,
    )


if __name__ == "__main__":
    main()
