"""From a mission file to a field plan: search, analyse, choose pairs, dither (section 4.4).

The stages of ``rapt-plan generate``, each a function a test can run on a small budget:

1. :func:`search_mission` — a space-filling start, then S-NDV on the root scores, every
   batch written to the study store (a killed run resumes where it stopped).
2. :func:`analyse` — every valid run re-scored in full (the simulator is deterministic),
   the sub-boundary tree over the mission's score tree, sensitivity of each root score.
3. :func:`select_pairs` — K boundary pairs on different sub-boundaries, shortest first,
   kept clear of invalid scenarios and of isolated samples (noise rather than behaviour);
   with ``--refine``, :func:`refine_pairs` bisects each pair on its own sub-scores.
4. :func:`dither_many` — Gaussian dithers around every chosen scenario re-simulated with
   the stochastic effects on: how likely each shows its predicted mode, the nearest
   boundary in its neighbourhood, and sub-boundaries there that the pair does not test
   (orthogonal: another kind of element; parallel: another element of the same kind).
5. :func:`robust_variants` — fragile scenarios moved away from their boundary ("M").

:func:`generate` runs them all and writes ``plan.json`` (schema ``rapt.plan/1``,
documented in ``planner/plan.schema.json``) and, per scenario, a QGroundControl
``.plan``, a ``QGC WPL 110`` file and its predicted track as GeoJSON
(:mod:`planner.exports`), and ``report.html`` (:mod:`planner.report`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

import rapt
import sim.uuv
from planner.exports import write_scenario_files
from planner.jsonio import jsonable
from planner.plans import coordinate_sensitivity
from planner.report import write_report
from planner.search_status import SearchStatus
from rapt.errors import InputError, StudyMismatchError
from rapt.importance import output_importance
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES, modes_from_scores

__all__ = [
    "GenerateConfig",
    "search_mission",
    "analyse",
    "select_pairs",
    "dither_many",
    "robust_variants",
    "refine_pairs",
    "generate",
    "auto_batch_size",
    "PLAN_SCHEMA",
]

PLAN_SCHEMA = "rapt.plan/1"


def auto_batch_size(budget: int) -> int:
    """About 40 batches of 250 to 5,000 runs.

    Small batches steer the search more often; large ones keep the vectorised simulator
    at full speed (its runs per second grow with the batch: ``benchmarks/sim_throughput.py``
    measures them by batch size on the machine at hand).
    """
    return int(np.clip(budget // 40, 250, 5000))


@dataclass
class GenerateConfig:
    budget: int = 3000
    pairs: int = 5
    global_fraction: float = 0.2
    seed: int = 0
    batch_size: int | None = None  # None: auto_batch_size(budget)
    dithers: int = 2000
    dither_sigma: float = 0.02
    executor: Any = None
    store: Path | None = None
    refine: int = 0  # runs per pair of the focused second search (0: off)
    refine_min_distance: float = 0.02  # refined pairs stay at least this far apart (unit cube)
    fragile_below: float = 0.8  # P(predicted mode) under which a scenario gets a robust variant
    surrogate: Any = None  # a sim.uuv.imitation Surrogate: search and dither with it, confirm pairs with the expert
    surrogate_file: str = ""
    confirm_runs: int = 100  # expert runs that check candidate pairs (two per pair)

    def __post_init__(self) -> None:
        if self.batch_size is None and isinstance(self.budget, int):
            self.batch_size = auto_batch_size(self.budget)

    def check(self) -> None:
        if not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise InputError(f"--batch-size: expected a positive number of runs, got {self.batch_size}")
        if not isinstance(self.budget, int) or self.budget < 2 * self.batch_size:
            raise InputError(f"--budget: expected at least {2 * self.batch_size} runs, got {self.budget}")
        if not (0 < self.global_fraction < 1):
            raise InputError(f"--global-fraction: expected a share in (0, 1), got {self.global_fraction}")
        if not isinstance(self.pairs, int) or self.pairs < 1:
            raise InputError(f"--pairs: expected a positive number of pairs, got {self.pairs}")
        if not isinstance(self.refine, int) or self.refine < 0:
            raise InputError(f"--refine-runs: expected runs per pair >= 0, got {self.refine}")
        if not isinstance(self.dithers, int) or self.dithers < 0:
            raise InputError(f"--dithers: expected a number of runs >= 0, got {self.dithers}")
        if not isinstance(self.confirm_runs, int) or self.confirm_runs < 2 * self.pairs:
            raise InputError(
                f"--confirm-runs: expected at least two runs per pair ({2 * self.pairs}), got {self.confirm_runs}"
            )


# -- 1. search --------------------------------------------------------------------------
@dataclass(frozen=True)
class MissionScores:
    """Every score of unit-cube scenarios (NaN rows for invalid ones); picklable, so it runs on any executor."""

    mission: Mission
    surrogate: Any = None  # fly a learned copy of the autonomy instead of the expert

    def __call__(self, U: np.ndarray) -> np.ndarray:
        return sim.uuv.simulate(self.mission, U, surrogate=self.surrogate).scores


ROOT_COLUMNS = (0, 1)  # mission and safety success: what the search steers on
# S-NDV's neighbours come from at most this many samples (rapt NNDVSampler.max_reference):
# a mission's parameters all matter, so its effective dimension is high and neighbour
# queries cost O(n) each; past this the asks of a 10^5-run study would dominate it.
SEARCH_REFERENCE = 10_000
SPOT_CHECK_RUNS = 8  # stored runs simulated again before an analysis trusts the store


def make_executor(spec: str):
    """``local`` (in process), ``processes`` (one per core) or ``dask://host:port``; returns (executor, close)."""
    if spec == "local":
        return None, lambda: None
    if spec == "processes":
        import concurrent.futures as cf
        import multiprocessing as mp
        import os

        pool = cf.ProcessPoolExecutor(max_workers=os.cpu_count() or 2, mp_context=mp.get_context("spawn"))
        return pool, lambda: pool.shutdown(cancel_futures=True)
    if spec.startswith("dask://"):
        try:
            from distributed import Client
        except ImportError:
            raise InputError("--executor: dask:// needs the cluster extra; pip install -e '.[cluster]'") from None
        client = Client(f"tcp://{spec[len('dask://') :]}", timeout=10)
        return client, client.close
    raise InputError(f"--executor: expected local, processes or dask://host:port, got {spec!r}")


def search_mission(
    mission: Mission,
    cfg: GenerateConfig,
    progress: Callable[[int, int], None] | None = None,
    on_batch: Callable[[np.ndarray, np.ndarray], None] | None = None,
) -> rapt.Study:
    """Global then adaptive search steered by mission and safety success; invalid scenarios fail.

    Every score is stored with its run, so the sub-boundary analysis needs no second run,
    and the neighbour graph the analysis pairs through grows with the batches (and is
    stored with them), so it need not be built once the search ends.
    """
    batch_size = auto_batch_size(cfg.budget) if cfg.batch_size is None else cfg.batch_size  # as __post_init__
    return rapt.search(
        MissionScores(mission, cfg.surrogate),
        mission.space,
        cfg.budget,
        method="s-ndv",
        batch_size=batch_size,
        seed=cfg.seed,
        store=cfg.store,
        executor=cfg.executor,
        output_types=("binary", "binary"),
        steer=ROOT_COLUMNS,
        sampler_options={"max_reference": SEARCH_REFERENCE},
        n_initial=int(round(cfg.budget * cfg.global_fraction)),
        progress=progress,
        on_batch=on_batch,
        neighbour_graph=12,  # subboundary_tree's k
    )


# -- 2. analysis --------------------------------------------------------------------------
@dataclass
class Analysis:
    X: np.ndarray
    result: sim.uuv.Result
    tree: rapt.SubBoundaryTree
    sensitivity: dict[str, dict[str, float]]
    X_invalid: np.ndarray
    boundary_types: list[dict] = field(default_factory=list)


def analyse(mission: Mission, study: rapt.Study, surrogate=None) -> Analysis:
    X, Y = study.X, study.Y
    names, types = metric_names(mission), metric_types(mission)
    spot = sim.uuv.simulate(mission, X[:SPOT_CHECK_RUNS], surrogate=surrogate)
    if Y.shape[1] != len(names) or not np.array_equal(spot.scores, Y[:SPOT_CHECK_RUNS], equal_nan=True):
        raise StudyMismatchError(
            "study: the stored runs do not match the mission file (was it edited?); plan into a new --out directory"
        )
    result = sim.uuv.Result(Y, modes_from_scores(Y), np.ones(len(Y), dtype=bool), [""] * len(Y), names, types)
    tree = rapt.subboundary_tree(
        X, result.scores, mission.score_tree, output_types=result.output_types, graph=study.neighbours
    )
    imp = output_importance(X, result.scores[:, :2], ("binary", "binary"), random_state=0)
    sensitivity = {}
    for row, name in zip(imp, ("mission_success", "safety_success")):
        sensitivity[name] = {p.name: float(row[mission.space.slice_of(p.name)].sum()) for p in mission.space.parameters}
    a = Analysis(X, result, tree, sensitivity, study.X_failed)
    a.boundary_types = _boundary_types(a)
    return a


def _pair_elements(a: Analysis, i: int, j: int, level: int) -> list[str]:
    """Names of the discrete score elements of ``level`` that differ across a pair."""
    cols = a.tree.levels[level]
    types = a.result.output_types
    return [
        a.result.names[c] for c in cols if types[c] != "continuous" and a.result.scores[i, c] != a.result.scores[j, c]
    ]


def _boundary_types(a: Analysis) -> list[dict]:
    i, j, d, lv = a.tree.pairs()
    counts: dict[tuple, list[float]] = {}
    for ii, jj, dd, ll in zip(i.tolist(), j.tolist(), d.tolist(), lv.tolist()):
        key = (ll, tuple(_pair_elements(a, ii, jj, ll)))
        if key[1]:
            counts.setdefault(key, []).append(dd)
    rows = [{"level": k[0], "elements": list(k[1]), "pairs": len(v), "shortest": min(v)} for k, v in counts.items()]
    return sorted(rows, key=lambda r: (r["level"], -r["pairs"], r["shortest"]))


# -- 3. pair selection --------------------------------------------------------------------
def select_pairs(a: Analysis, k: int, min_cluster: int = 3) -> list[dict]:
    """K pairs on distinct sub-boundaries: root-mode changes first, then deeper elements.

    A pair is skipped when an endpoint's sub-cluster at the pair's level has fewer than
    ``min_cluster`` runs (a lone run is more likely noise than a behaviour), or when an
    invalid scenario lies closer to an endpoint than the pair's own length.
    """
    i, j, d, lv = a.tree.pairs()
    invalid = cKDTree(a.X_invalid) if len(a.X_invalid) else None
    sizes = [np.bincount(a.tree.assignment[level]) for level in range(len(a.tree.levels))]
    chosen, seen = [], set()
    for ii, jj, dd, ll in sorted(zip(i.tolist(), j.tolist(), d.tolist(), lv.tolist()), key=lambda p: (p[3] > 0, p[2])):
        elements = tuple(_pair_elements(a, ii, jj, ll))
        if not elements or (ll, elements) in seen:
            continue
        asg = a.tree.assignment[ll]
        if min(sizes[ll][asg[ii]], sizes[ll][asg[jj]]) < min_cluster:
            continue
        if invalid is not None:
            near, _ = invalid.query(a.X[[ii, jj]], k=1)
            if np.any(near < dd):
                continue
        seen.add((ll, elements))
        modes = a.result.modes
        chosen.append(
            {
                "level": ll,
                "elements": list(elements),
                "distance": dd,
                "rows": [ii, jj],
                "modes": [MODE_NAMES[modes[ii]], MODE_NAMES[modes[jj]]],
            }
        )
        if len(chosen) == k:
            break
    return chosen


# -- 4. dithering ---------------------------------------------------------------------------
def dither_many(
    mission: Mission,
    centres: np.ndarray,
    predicted: np.ndarray | Sequence[int],
    elements: Sequence[list[str]],
    n: int,
    sigma: float,
    seed: int,
    surrogate=None,
) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Stochastic runs of ``n`` Gaussian dithers around each centre, all in one batch.

    Returns per centre the statistics of :func:`dither_stats`, and the dithers' unit-cube
    rows and modes, (k, n, d) and (k, n), for the report.  The first dither of each centre
    is the centre itself, with the stochastic effects on.
    """
    centres = np.atleast_2d(np.asarray(centres, dtype=float))
    k, d = centres.shape
    rng = np.random.default_rng(seed)
    U = np.clip(centres[:, None, :] + sigma * rng.standard_normal((k, n, d)), 0.0, 1.0)
    U[:, 0] = centres
    r = sim.uuv.simulate(mission, U.reshape(k * n, d), seed=seed, stochastic=True, surrogate=surrogate)
    stats = []
    for c in range(k):
        rows = slice(c * n, (c + 1) * n)
        stats.append(
            dither_stats(
                U[c],
                r.scores[rows],
                r.modes[rows],
                r.valid[rows],
                r.names,
                r.output_types,
                int(predicted[c]),
                list(elements[c]),
                sigma,
            )
        )
    return stats, U, r.modes.reshape(k, n)


def dither_stats(
    U: np.ndarray,
    scores: np.ndarray,
    modes: np.ndarray,
    valid: np.ndarray,
    names: list[str],
    types: Sequence[str],
    predicted_mode: int,
    elements: list[str],
    sigma: float,
) -> dict:
    """Reproducibility and neighbours of one dithered scenario (sections 4.4.5-4.4.7).

    How often the predicted mode shows, how close the nearest run of another mode lies,
    and which sub-boundaries the neighbourhood holds that the pair does not test: an
    element that flips among runs of the predicted mode is *parallel* when it is of the
    same kind as the pair's elements (another no-go area), *orthogonal* otherwise.
    """
    u = U[0]
    out: dict[str, Any] = {"runs": int(U.shape[0]), "valid": int(valid.sum()), "sigma": sigma}
    if not valid.any():
        return out
    dist = np.linalg.norm(U[valid] - u, axis=1)
    modes = modes[valid]
    out["p_predicted_mode"] = float(np.mean(modes == predicted_mode))
    out["modes"] = {MODE_NAMES[m]: int(c) for m, c in zip(*np.unique(modes, return_counts=True))}
    other = modes != predicted_mode
    out["nearest_other_mode"] = float(dist[other].min()) if other.any() else None
    same = scores[valid][~other]
    flips: list[dict[str, str | float]] = []
    if same.shape[0] > 1 and valid[0]:
        ref = scores[0]
        for c, (name, t) in enumerate(zip(names, types)):
            if t == "continuous" or "." not in name or name in elements:
                continue
            differ = same[:, c] != ref[c]
            if differ.any():
                kind = name.split(".")[0]
                relation = "parallel" if any(e.split(".")[0] == kind for e in elements) else "orthogonal"
                flips.append(
                    {
                        "element": name,
                        "relation": relation,
                        "share": float(differ.mean()),
                        "nearest": float(dist[~other][differ].min()),
                    }
                )
    out["sub_boundaries"] = sorted(flips, key=lambda f: f["nearest"])[:8]
    return out


# -- 5. robust variants ---------------------------------------------------------------------
VARIANT_STEPS = (0.02, 0.05, 0.1)
VARIANT_COORDINATES = 2  # the most sensitive coordinates tried


def robust_variants(
    mission: Mission,
    fragile: np.ndarray,
    partners: np.ndarray,
    modes: np.ndarray | Sequence[int],
    sensitivity: np.ndarray,
    n: int,
    sigma: float,
    target: float,
    seed: int,
    surrogate=None,
) -> list[dict | None]:
    """Move fragile scenarios away from their boundary along their most sensitive coordinates.

    For each scenario the candidates step away from the pair's other scenario along the
    ``VARIANT_COORDINATES`` most sensitive coordinates by ``VARIANT_STEPS`` (unit cube); the
    first candidate, in that order, whose deterministic run keeps the predicted mode and
    whose dithers show it at least ``target`` of the time wins (section 4.5.3's "M"
    scenarios); None where none does.  All candidates run in two batches.
    """
    fragile = np.atleast_2d(np.asarray(fragile, dtype=float))
    cands, owner, meta = [], [], []
    for s, (u, partner) in enumerate(zip(fragile, np.atleast_2d(partners))):
        for c in np.argsort(-sensitivity, kind="stable")[:VARIANT_COORDINATES]:
            direction = np.sign(u[c] - partner[c]) or 1.0
            for step in VARIANT_STEPS:
                v = u.copy()
                v[c] = np.clip(v[c] + direction * step, 0.0, 1.0)
                if v[c] == u[c]:
                    break
                cands.append(v)
                owner.append(s)
                meta.append((int(c), float(v[c] - u[c])))
    out: list[dict | None] = [None] * len(fragile)
    if not cands:
        return out
    V, owners = np.array(cands), np.array(owner)
    det = sim.uuv.simulate(mission, V, surrogate=surrogate)
    keep = np.flatnonzero(det.valid & (det.modes == np.asarray(modes)[owners]))
    if keep.size == 0:
        return out
    stats, _, _ = dither_many(
        mission, V[keep], np.asarray(modes)[owners[keep]], [[]] * keep.size, n, sigma, seed, surrogate
    )
    for idx, st in zip(keep.tolist(), stats):
        s = owners[idx]
        if out[s] is None and st.get("p_predicted_mode", 0.0) >= target:
            c, step = meta[idx]
            out[s] = {
                "u": [float(x) for x in V[idx]],
                "coordinate": c,
                "step": step,
                "p_predicted_mode": st["p_predicted_mode"],
            }
    return out


# -- 6. refinement ----------------------------------------------------------------------------
def refine_pairs(
    mission: Mission, a: Analysis, pairs: list[dict], runs: int, min_distance: float = 0.02, surrogate=None
) -> list[dict]:
    """Sharpen pairs with a search focused on their own sub-scores (section 4.3.6).

    Bisection on the segment between each pair's two scenarios: each run is scored on the
    pair's elements only, and replaces the end whose element values it shares, so the pair
    keeps straddling the same sub-boundary while its length halves per run (``runs`` at
    most).  A run showing a third combination (another sub-boundary between them) or an
    invalid scenario stops that pair's search, and so does ``min_distance``: two scenarios
    closer than that cannot be told apart on the water (section 4.1: straddle the boundary
    without being too close together).  All pairs bisect in step, one batch per run.
    """
    names = a.result.names
    cols = [[names.index(e) for e in pair["elements"]] for pair in pairs]
    lo = np.array([a.X[pair["rows"][0]] for pair in pairs]).reshape(len(pairs), -1)
    hi = np.array([a.X[pair["rows"][1]] for pair in pairs]).reshape(len(pairs), -1)
    side_lo = [a.result.scores[p["rows"][0], c] for p, c in zip(pairs, cols)]
    side_hi = [a.result.scores[p["rows"][1], c] for p, c in zip(pairs, cols)]
    active = np.ones(len(pairs), dtype=bool)
    for _ in range(runs):
        active &= np.linalg.norm(hi - lo, axis=1) / 2 >= min_distance
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        mid = (lo[rows] + hi[rows]) / 2
        r = sim.uuv.simulate(mission, mid, surrogate=surrogate)
        for k, row in enumerate(rows.tolist()):
            y = r.scores[k, cols[row]]
            if r.valid[k] and np.array_equal(y, side_lo[row]):
                lo[row] = mid[k]
            elif r.valid[k] and np.array_equal(y, side_hi[row]):
                hi[row] = mid[k]
            else:
                active[row] = False
    d = np.linalg.norm(hi - lo, axis=1)
    better = np.flatnonzero(d < np.array([p["distance"] for p in pairs]))
    out = list(pairs)
    if better.size:
        r = sim.uuv.simulate(mission, np.vstack([lo[better], hi[better]]), surrogate=surrogate)
        for k, row in enumerate(better.tolist()):
            out[row] = {
                **pairs[row],
                "distance": float(d[row]),
                "refined": True,
                "u_override": [lo[row], hi[row]],
                "modes": [MODE_NAMES[r.modes[k]], MODE_NAMES[r.modes[better.size + k]]],
            }
    return out


# -- 7. expert confirmation (surrogate workflow) ------------------------------------------------
def confirm_with_expert(mission: Mission, a: Analysis, candidates: list[dict], k: int) -> tuple[list[dict], int]:
    """Run the expert on both scenarios of each candidate pair; keep the first ``k`` it confirms.

    Section 6.2.3, step 3: a pair found on the surrogate is a boundary of the real autonomy
    when the expert's modes differ across it too.  The pair's ``modes`` become the expert's
    (the surrogate's are kept as ``surrogate_modes``).  Returns (pairs, expert runs).
    """
    if not candidates:
        return [], 0
    U = np.vstack([np.asarray(p.get("u_override", [a.X[r] for r in p["rows"]])) for p in candidates])
    r = sim.uuv.simulate(mission, U)
    out = []
    for c, pair in enumerate(candidates):
        ma, mb = int(r.modes[2 * c]), int(r.modes[2 * c + 1])
        if r.valid[2 * c] and r.valid[2 * c + 1] and ma != mb:
            out.append(
                {
                    **pair,
                    "confirmed_by_expert": True,
                    "surrogate_modes": pair["modes"],
                    "modes": [MODE_NAMES[ma], MODE_NAMES[mb]],
                }
            )
            if len(out) == k:
                break
    return out, int(len(U))


# -- everything ------------------------------------------------------------------------------
def generate(
    mission: Mission,
    mission_path: Path,
    out_dir: Path,
    cfg: GenerateConfig,
    progress: Callable[[str, int, int, str], None] | None = None,
    timings: dict[str, float] | None = None,
) -> dict:
    """Run every stage and write ``plan.json`` (plus per-scenario files and the report) into ``out_dir``.

    ``progress(stage, done, total, detail)`` follows the stages; during the search
    ``detail`` says how many modes and boundary links the runs so far show
    (:class:`~planner.search_status.SearchStatus`).  ``timings``, when given, receives the
    wall seconds of each stage (kept out of the plan, which depends on the seed only).
    """
    cfg.check()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    clock = _StageClock(timings)
    a, pairs, confirmation = _choose_pairs(mission, cfg, progress, clock)
    sens = coordinate_sensitivity(mission.space, a.sensitivity)
    U = (
        np.vstack([np.asarray(p.get("u_override", [a.X[r] for r in p["rows"]])) for p in pairs])
        if pairs
        else np.zeros((0, mission.dim))
    )
    ids = [f"pair{p}{side}" for p in range(1, len(pairs) + 1) for side in "ab"]
    partners = U[np.arange(len(U)) ^ 1]  # a's partner is b and b's is a
    chosen = sim.uuv.simulate(mission, U, trajectories=True)
    stats, dither_runs = _dither_chosen(mission, cfg, U, ids, chosen, pairs, progress)
    clock.lap("dithering")
    fragile = [k for k, st in enumerate(stats) if st.get("p_predicted_mode", 1.0) < cfg.fragile_below]
    found = (
        robust_variants(
            mission,
            U[fragile],
            partners[fragile],
            chosen.modes[fragile],
            sens,
            max(cfg.dithers // 10, 20),
            cfg.dither_sigma,
            cfg.fragile_below,
            cfg.seed + 1,
            cfg.surrogate,
        )
        if fragile and cfg.dithers
        else []
    )
    clock.lap("variants")
    scenarios = _scenario_entries(mission, a, U, ids, chosen, stats, out_dir)
    variants = _variant_entries(mission, ids, fragile, found, chosen, out_dir)
    plan = _plan_document(mission, mission_path, cfg, a, pairs, confirmation, scenarios, variants)
    (out_dir / "plan.json").write_text(json.dumps(plan, indent=2))
    write_report(plan, out_dir, dither_runs)
    clock.lap("files")
    return plan


def _choose_pairs(
    mission: Mission, cfg: GenerateConfig, progress: Callable[[str, int, int, str], None] | None, clock: _StageClock
) -> tuple[Analysis, list[dict], tuple[int, int] | None]:
    """Stages 1-3 (with refinement, and the expert's confirmation on the surrogate workflow).

    Returns the analysis, the chosen pairs, and on the surrogate workflow the number of
    candidate pairs and the expert runs that checked them (None otherwise).
    """
    status: SearchStatus | None = None
    searched: Callable[[int, int], None] | None = None
    if progress is not None:
        status = SearchStatus(mission.dim)
        searched = _search_progress(progress, status)
    study = search_mission(mission, cfg, searched, on_batch=status)
    clock.lap("search")
    sur = cfg.surrogate
    a = analyse(mission, study, sur)
    clock.lap("analysis")
    pairs = select_pairs(a, cfg.pairs if sur is None else cfg.confirm_runs // 2)
    clock.lap("selection")
    if cfg.refine:
        pairs = refine_pairs(mission, a, pairs, cfg.refine, cfg.refine_min_distance, sur)
        if progress is not None:
            progress("refine", len(pairs), len(pairs), "")
        clock.lap("refinement")
    confirmation = None
    if sur is not None:
        candidates = len(pairs)
        pairs, confirm_spent = confirm_with_expert(mission, a, pairs, cfg.pairs)
        if progress is not None:
            progress("confirm", len(pairs), candidates, f"{len(pairs)} of {candidates} candidate pairs confirmed")
        clock.lap("confirmation")
        confirmation = (candidates, confirm_spent)
    return a, pairs, confirmation


def _search_progress(
    progress: Callable[[str, int, int, str], None], status: SearchStatus
) -> Callable[[int, int], None]:
    """The search's ``progress``: runs done of the budget, and what the runs so far show (``status``)."""
    return lambda done, total: progress("search", done, total, status.summary())


def _dither_chosen(
    mission: Mission,
    cfg: GenerateConfig,
    U: np.ndarray,
    ids: list[str],
    chosen: sim.uuv.Result,
    pairs: list[dict],
    progress: Callable[[str, int, int, str], None] | None,
) -> tuple[list[dict], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Stage 4 on the chosen scenarios: their dither statistics, and the dithers by scenario for the report."""
    elements = [pair["elements"] for pair in pairs for _ in "ab"]
    stats: list[dict] = [{} for _ in ids]
    dither_runs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if cfg.dithers and len(U):
        stats, dU, dmodes = dither_many(
            mission, U, chosen.modes, elements, cfg.dithers // 2, cfg.dither_sigma, cfg.seed, cfg.surrogate
        )
        dither_runs = {sid: (dU[k], dmodes[k]) for k, sid in enumerate(ids)}
        if progress is not None:
            progress("dither", len(ids), len(ids), "")
    return stats, dither_runs


def _scenario_entries(
    mission: Mission,
    a: Analysis,
    U: np.ndarray,
    ids: list[str],
    chosen: sim.uuv.Result,
    stats: list[dict],
    out_dir: Path,
) -> list[dict]:
    """The plan's scenarios (with their predicted root and level-1 scores), their files written."""
    level_cols = set(a.tree.levels[0]) | set(a.tree.levels[min(1, len(a.tree.levels) - 1)])
    scenarios = []
    for k, sid in enumerate(ids):
        mode = int(chosen.modes[k])
        scenarios.append(
            {
                "id": sid,
                "u": [float(v) for v in U[k]],
                "parameters": jsonable(mission.space.decode(U[k][None, :])[0]),
                "predicted": {
                    "mode": MODE_NAMES[mode],
                    "scores": {n: float(chosen.scores[k, c]) for c, n in enumerate(chosen.names) if c in level_cols},
                },
                "dithering": stats[k],
                "files": {
                    kind: path.name
                    for kind, path in write_scenario_files(mission, U[k], out_dir, sid, chosen.trajectory(k)).items()
                },
            }
        )
    return scenarios


def _variant_entries(
    mission: Mission,
    ids: list[str],
    fragile: list[int],
    found: list[dict | None],
    chosen: sim.uuv.Result,
    out_dir: Path,
) -> list[dict]:
    """The robust "M" variants found for fragile scenarios, their files written."""
    variants = []
    for k, v in zip(fragile, found):
        if v is None:
            continue
        vid = f"{ids[k]}M"
        variants.append(
            {
                "id": vid,
                "variant_of": ids[k],
                "u": v["u"],
                "parameters": jsonable(mission.space.decode(np.array(v["u"])[None, :])[0]),
                "moved": {"parameter": mission.parameter_of(v["coordinate"]), "unit_step": v["step"]},
                "predicted": {"mode": MODE_NAMES[int(chosen.modes[k])]},
                "p_predicted_mode": v["p_predicted_mode"],
                "files": {
                    kind: path.name
                    for kind, path in write_scenario_files(mission, np.array(v["u"]), out_dir, vid).items()
                },
            }
        )
    return variants


def _plan_document(
    mission: Mission,
    mission_path: Path,
    cfg: GenerateConfig,
    a: Analysis,
    pairs: list[dict],
    confirmation: tuple[int, int] | None,
    scenarios: list[dict],
    variants: list[dict],
) -> dict:
    """What ``plan.json`` holds (schema ``rapt.plan/1``)."""
    sur = cfg.surrogate
    plan_pairs = [
        {
            "id": p,
            "level": pair["level"],
            "elements": pair["elements"],
            "modes": pair["modes"],
            "distance": pair["distance"],
            "scenarios": [f"pair{p}a", f"pair{p}b"],
            "refined": bool(pair.get("refined", False)),
            **({"confirmed_by_expert": True, "surrogate_modes": pair["surrogate_modes"]} if sur is not None else {}),
        }
        for p, pair in enumerate(pairs, start=1)
    ]
    modes = a.result.modes
    return {
        "schema": PLAN_SCHEMA,
        "mission": {
            "name": mission.name,
            "file": str(mission_path),
            "dim": mission.dim,
            "parameters": mission.space.names,
        },
        "study": {
            "budget": cfg.budget,
            "seed": cfg.seed,
            "global_fraction": cfg.global_fraction,
            "valid_runs": int(len(a.X)),
            "invalid_runs": int(len(a.X_invalid)),
            "modes": {MODE_NAMES[m]: int(c) for m, c in zip(*np.unique(modes, return_counts=True))},
            "boundary_types": a.boundary_types[:30],
            **({"surrogate": _surrogate_summary(cfg, confirmation, len(pairs))} if confirmation is not None else {}),
        },
        "sensitivity": a.sensitivity,
        "pairs": plan_pairs,
        "scenarios": scenarios,
        "variants": variants,
        "run_order": [s["id"] for s in scenarios] + [v["id"] for v in variants],
    }


def _surrogate_summary(cfg: GenerateConfig, confirmation: tuple[int, int], confirmed: int) -> dict:
    """The plan's account of a surrogate search: its file and method, expert runs, pairs confirmed."""
    sur = cfg.surrogate
    candidates, confirm_spent = confirmation
    return {
        "file": cfg.surrogate_file,
        "method": str(sur.training.get("method", "")),
        "expert_runs": {"training": int(sur.training.get("runs", 0)), "confirmation": confirm_spent},
        "candidates": candidates,
        "confirmed": confirmed,
    }


class _StageClock:
    """Wall seconds per stage into a caller's dict (or nowhere)."""

    def __init__(self, into: dict[str, float] | None):
        self.into = into
        self.last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        if self.into is not None:
            self.into[stage] = self.into.get(stage, 0.0) + now - self.last
        self.last = now
