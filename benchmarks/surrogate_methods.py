"""Table 5 of ``benchmarks/surrogate.py``: the dissertation's Table 6.3, the imitation learners side by side.

Supervised learning (behavioural cloning: the expert flies every run, all data kept),
DAgger, Q-DAgger(50) and Q-DAgger(75) (Algorithm 9: the aggregate re-mined to its worst
half, or quarter, after every update) are each trained at section 6.6.1's budget: 50
updates of 5 expert-annotated runs, 250 in all, on uniformly drawn scenarios (the paper's
"5 randomly generated scenarios" per iteration).  Beside them every learner gets the
same 50 held-out expert runs, which choose the update kept and the goal threshold
(``rapt-plan surrogate``'s practice; the paper does not say which update it kept).

Each surrogate is then flown on the same Sobol validation set as the expert:

* *run time* — the training's wall time (expert and learner runs, fits, selection) and
  the fits' CPU seconds, one BLAS thread; the paper's column is wall time on a GPU
  workstation, so the ratios to DAgger are what compare;
* *score accuracy* — the share of valid validation scenarios ending in the expert's mode;
* *path error* — mean per-step distance between the expert's and the surrogate's tracks
  (:func:`rapt.agreement.path_error`) over the first ``paths`` valid scenarios.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.stats import qmc

import sim.uuv
from planner.plan.surrogate import train_surrogate
from rapt.agreement import path_error

__all__ = ["methods_table", "PAPER", "LEARNERS", "BUDGET"]

#: The learners of Table 6.3: (label, rapt-plan surrogate --method, quantile).
LEARNERS = {
    "supervised": ("Supervised", "supervised", 0.0),
    "dagger": ("DAgger", "dagger", 0.0),
    "qdagger50": ("Q-DAgger(50)", "qdagger", 0.5),
    "qdagger75": ("Q-DAgger(75)", "qdagger", 0.75),
}
#: Table 6.3 as printed: run time (minutes), score accuracy, path error (m).
PAPER = {
    "supervised": (372, 0.06, 525.0),
    "dagger": (461, 0.85, 70.0),
    "qdagger50": (152, 0.84, 61.0),
    "qdagger75": (132, 0.81, 87.0),
}
#: Section 6.6.1: 50 iterations of 5 annotated runs; our 50 held-out runs come on top.
BUDGET = {"runs": 250, "runs_per_iteration": 5, "select_runs": 50, "directed": False}


def _train(mission, key: str, budget: dict, seed: int):
    """One learner at ``budget``: (surrogate, wall s, fit CPU s, samples in its last training set)."""
    from threadpoolctl import threadpool_limits

    _, method, quantile = LEARNERS[key]
    records: list = []
    t0 = time.perf_counter()
    with threadpool_limits(1):
        sur = train_surrogate(
            mission,
            method=method,
            quantile=quantile,
            seed=seed,
            on_iteration=lambda rec, _policy: records.append(rec),
            **budget,
        )
    wall = time.perf_counter() - t0
    return sur, wall, float(sum(r.fit_cpu_s for r in records)), records[-1].samples


def _flown(mission, sur, X: np.ndarray, expert, tracks: list, rows: np.ndarray) -> tuple[float, float]:
    """(score accuracy on the valid scenarios of ``X``, path error over ``rows``) of one surrogate."""
    mine = sim.uuv.simulate(mission, X, surrogate=sur)
    ok = expert.valid & mine.valid
    accuracy = float(np.mean(mine.modes[ok] == expert.modes[ok]))
    paths = sim.uuv.simulate(mission, X[rows], surrogate=sur, trajectories=True).trajectories or []
    return accuracy, path_error(tracks, [None if t is None else t[:, 1:3] for t in paths])


def methods_table(
    mission, keys: list[str], n: int, paths: int, seed: int, budget: dict | None = None
) -> dict[str, dict]:
    """Print Table 6.3 (``keys`` of :data:`LEARNERS`, ``n`` Sobol validation scenarios); returns the figures."""
    budget = {**BUDGET, **(budget or {})}
    X = qmc.Sobol(mission.dim, seed=seed).random(n)
    expert = sim.uuv.simulate(mission, X)
    rows = np.flatnonzero(expert.valid)[:paths]
    flown = sim.uuv.simulate(mission, X[rows], trajectories=True).trajectories or []
    tracks = [None if t is None else t[:, 1:3] for t in flown]
    print(
        f"5. Table 6.3: the learners at {budget['runs']} annotated runs ({budget['runs_per_iteration']} per update, "
        f"{budget['runs'] // budget['runs_per_iteration']} updates, "
        f"{'directed' if budget['directed'] else 'uniform'}) + {budget['select_runs']} held out, seed {seed}; "
        f"score accuracy on {int(expert.valid.sum()):,} valid Sobol scenarios, path error on the first {len(rows)}",
        flush=True,
    )
    out: dict[str, dict] = {}
    for key in keys:
        sur, wall, fit, samples = _train(mission, key, budget, seed)
        accuracy, perr = _flown(mission, sur, X, expert, tracks, rows)
        out[key] = {"wall_s": wall, "fit_cpu_s": fit, "accuracy": accuracy, "path_m": perr, "samples": samples}
        out[key]["kept"] = sur.training["chosen_iteration"]
        print(
            f"   {key:<11} trained in {wall:6.0f} s (fits {fit:6.1f} CPU s, {samples:,} states at the end, "
            f"update {out[key]['kept']} kept): accuracy {accuracy:.1%}, path error {perr:.1f} m",
            flush=True,
        )
    _print(out)
    return out


def _print(out: dict[str, dict]) -> None:
    """The table in the paper's layout: one column per learner, ours beside the paper's."""
    keys = list(out)
    print(f"\n{'metric (ours | paper)':<26}" + "".join(f"{LEARNERS[k][0]:>24}" for k in keys))
    ref = out.get("dagger")
    lines = [
        ("run time", lambda k: f"{out[k]['wall_s'] / 60:.1f} min | {_hm(PAPER[k][0])}"),
        ("fit, CPU s", lambda k: f"{out[k]['fit_cpu_s']:.0f} | -"),
        (
            "run time / DAgger's",
            lambda k: (
                f"{out[k]['wall_s'] / ref['wall_s']:.2f} | {PAPER[k][0] / PAPER['dagger'][0]:.2f}" if ref else "-"
            ),
        ),
        ("score accuracy", lambda k: f"{out[k]['accuracy']:.1%} | {PAPER[k][1]:.0%}"),
        ("path error (m)", lambda k: f"{out[k]['path_m']:.1f} | {PAPER[k][2]:.0f}"),
        ("states at the end", lambda k: f"{out[k]['samples']:,} | -"),
    ]
    for name, cell in lines:
        print(f"{name:<26}" + "".join(f"{cell(k):>24}" for k in keys))
    print()


def _hm(minutes: int) -> str:
    return f"{minutes // 60}h {minutes % 60:02d}m"
