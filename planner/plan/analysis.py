"""What a study's runs show and which boundary pairs to fly: stages 2, 3 and 7 of ``rapt-plan generate``.

2. :func:`analyse` — every valid run re-scored in full (the simulator is deterministic),
   the sub-boundary tree over the mission's score tree, sensitivity of each root score and
   the boundary types (score-tree level and the elements that flip across a pair).
3. :func:`select_pairs` — K boundary pairs on different sub-boundaries, shortest first,
   kept clear of invalid scenarios and of isolated samples (noise rather than behaviour).
7. :func:`confirm_with_expert` — on the surrogate workflow, the candidate pairs checked
   by the expert autonomy.

:func:`planner.plan.generate.generate` runs them between the search and the dithering.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

import rapt
import sim.uuv
from planner.plan.confirmation import Confirmation, confirm_pairs
from rapt.errors import StudyMismatchError
from rapt.importance import output_importance
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES, modes_from_scores

__all__ = ["Analysis", "analyse", "select_pairs", "confirm_with_expert", "pair_points", "pairs_across"]

SPOT_CHECK_RUNS = 8  # stored runs simulated again before an analysis trusts the store


@dataclass
class Analysis:
    """What the study's valid runs show: their scores, the sub-boundary tree, sensitivity and boundary types."""

    X: np.ndarray
    result: sim.uuv.Result
    tree: rapt.SubBoundaryTree
    sensitivity: dict[str, dict[str, float]]
    X_invalid: np.ndarray
    boundary_types: list[dict] = field(default_factory=list)
    surrogate: Any = None  # the learned autonomy the runs were simulated with (None: the expert)


def analyse(mission: Mission, study: rapt.Study, surrogate=None, stochastic_seed: int | None = None) -> Analysis:
    """Stage 2: every valid run re-scored in full, the sub-boundary tree, each root score's sensitivity.

    A few stored runs are simulated again first: a store of another mission file is refused.
    ``stochastic_seed``: the study ran stochastic with this seed (``--noisy-search``), so they are too.
    """
    X, Y = study.X, study.Y
    names, types = metric_names(mission), metric_types(mission)
    spot = sim.uuv.simulate(
        mission,
        X[:SPOT_CHECK_RUNS],
        seed=stochastic_seed or 0,
        stochastic=stochastic_seed is not None,
        surrogate=surrogate,
    )
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
    a = Analysis(X, result, tree, sensitivity, study.X_failed, surrogate=surrogate)
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


# -- 7. expert confirmation (surrogate workflow) ------------------------------------------------
def confirm_with_expert(mission: Mission, a: Analysis, candidates: list[dict], k: int, budget: int) -> Confirmation:
    """The surrogate's candidate pairs checked by the expert (:func:`planner.plan.confirmation.confirm_pairs`).

    Section 6.2.3, step 3: a pair found on the surrogate is planned only as the expert's own
    boundary pair near it.  The candidates' scenarios and the surrogate's scores there
    (simulated again: the surrogate is deterministic) are handed on; at most ``k`` pairs,
    at most ``budget`` expert runs.
    """
    U = np.array([pair_points(a, p) for p in candidates]).reshape(len(candidates), 2, mission.dim)
    claimed = sim.uuv.simulate(mission, U.reshape(-1, mission.dim), surrogate=a.surrogate).scores
    offered = [{**p, "u": U[c], "scores": claimed[2 * c : 2 * c + 2]} for c, p in enumerate(candidates)]
    return confirm_pairs(mission, offered, k, budget)


def pair_points(a: Analysis, pair: dict) -> np.ndarray:
    """A pair's two unit-cube scenarios: moved ones (refined or confirmed) or the study's rows."""
    return np.asarray(pair["u_override"] if "u_override" in pair else a.X[pair["rows"]], dtype=float)


def pairs_across(a: Analysis, level: int, elements: list[str]) -> list[tuple[int, int, float]]:
    """The study's boundary pairs of one type (its level, and the elements that differ across it), shortest first:
    (row, row, unit-cube distance)."""
    i, j, d, lv = a.tree.pairs()
    want = list(elements)
    out = [
        (ii, jj, dd)
        for ii, jj, dd, ll in zip(i.tolist(), j.tolist(), d.tolist(), lv.tolist())
        if ll == level and _pair_elements(a, ii, jj, ll) == want
    ]
    return sorted(out, key=lambda p: p[2])
