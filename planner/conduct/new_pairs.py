"""A boundary that has fallen through, tested again: a new pair across it, from the noon study.

When a pair can no longer be confirmed with the runs left (both its sides, moved or not,
out of reach), its boundary may still be shown elsewhere.  The noon search holds every
boundary pair it found (the plan directory's study store): :func:`study_alternatives` takes,
per plan pair, the shortest few of the same type (level and differing elements) on other
stretches of the boundary (their midpoints at least :data:`MIN_APART` from the pair's and from
each other's), and no longer than a plan's flown pair may be (the pair's own length or
:data:`planner.plan.pair_choice.MAX_FLOWN_DISTANCE`, whichever is longer: farther apart, the
switch between its sides is no longer one boundary's).  It
reads the store once an afternoon, at the first call, and the rows are kept in the day's
record.  :func:`candidate` writes one at the range's resolution, keeps it only when its two
sides still differ on the pair's elements in the plan's prediction, and ``rapt-plan next``
forecasts it like any side; :func:`add_pair` writes a chosen one into the plan as a pair with
its origin (which pair it replaces, and why), its two scenarios and their range files.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

import sim.uuv
from planner.common.atomic import write_text_atomic
from planner.common.jsonio import jsonable
from planner.common.plans import Plan
from planner.conduct.side_forecast import DRAWS, SCALES
from planner.plan.analysis import analyse, pairs_across
from planner.plan.exports import write_scenario_files
from planner.plan.generate import GenerateConfig, auto_batch_size, search_mission
from planner.plan.pair_choice import MAX_FLOWN_DISTANCE
from rapt.errors import RaptError
from sim.uuv.scoring import MODE_NAMES

__all__ = ["ALTERNATIVES", "MIN_APART", "NewPair", "study_alternatives", "candidate", "new_pair_id", "add_pair"]

#: Other pairs kept per plan pair, shortest first.
ALTERNATIVES = 3
#: A new pair lies at least this far (unit cube) from the pair it replaces and from the other new ones.
MIN_APART = 0.1


@dataclass
class NewPair:
    """A pair across the boundary of plan pair ``replaces``, as written (rows) and predicted (score rows)."""

    replaces: int
    U: np.ndarray  # (2, d)
    scores: np.ndarray  # (2, m)
    distance: float


def study_alternatives(plan: Plan) -> dict[str, list[list[list[float]]]]:
    """Per plan pair id (as a string): up to :data:`ALTERNATIVES` other study pairs across its boundary, as unit
    rows; empty when the plan has no study store of its own search (a surrogate's, or a plan made elsewhere)."""
    store = plan.path.parent / "study.db"
    st = plan.data.get("study", {})
    if not store.is_file() or "surrogate" in st or "search" not in st.get("runs", {}):
        return {}
    cfg = GenerateConfig(
        budget=int(st["runs"]["search"]),
        batch_size=auto_batch_size(int(st["budget"])),
        seed=int(st["seed"]),
        global_fraction=float(st["global_fraction"]),
        store=store,
    )
    try:
        a = analyse(plan.mission, search_mission(plan.mission, cfg))
    except (RaptError, ValueError, KeyError):
        return {}  # a store this plan's search did not write: no alternatives
    out: dict[str, list[list[list[float]]]] = {}
    for pair in plan.pairs:
        longest = max(MAX_FLOWN_DISTANCE, float(pair.get("distance", 0.0)))
        taken = [(plan.u(pair["scenarios"][0]) + plan.u(pair["scenarios"][1])) / 2]  # the pair's own stretch
        rows: list[list[list[float]]] = []
        for i, j, d in pairs_across(a, int(pair.get("level", 0)), list(pair.get("elements", []))):
            if d > longest:
                break  # shortest first: the rest are longer still
            mid = (a.X[i] + a.X[j]) / 2
            if min(float(np.linalg.norm(mid - t)) for t in taken) < MIN_APART:
                continue
            rows.append([a.X[i].tolist(), a.X[j].tolist()])
            taken.append(mid)
            if len(rows) == ALTERNATIVES:
                break
        out[str(pair["id"])] = rows
    return out


def candidate(plan: Plan, pair: dict, rows: list[list[float]], names: list[str]) -> NewPair | None:
    """One stored alternative written at the range's resolution and predicted; None when its sides no longer
    differ on the pair's elements, lie farther apart than a flown pair may, or a side is not a valid run."""
    m = plan.mission
    U = m.space.snap(np.asarray(rows, dtype=float))
    r = sim.uuv.simulate(m, U)
    if not r.valid.all():
        return None
    cols = [names.index(e) for e in pair.get("elements", []) if e in names] or [0, 1]
    distance = float(np.linalg.norm(U[0] - U[1]))
    if np.array_equal(r.scores[0, cols], r.scores[1, cols]) or distance > max(MAX_FLOWN_DISTANCE, pair["distance"]):
        return None
    return NewPair(int(pair["id"]), U, r.scores, distance)


def new_pair_id(plan: Plan) -> int:
    """The id the next new pair gets: one past the plan's largest."""
    return max(int(p["id"]) for p in plan.pairs) + 1


def add_pair(
    plan: Plan, new: NewPair, names: list[str], reason: str, after_logs: list[str], p_sides: list[float]
) -> list[str]:
    """Write ``new`` into the plan as pair ``max id + 1`` (scenarios ``pair<N>a``, ``pair<N>b``, their range
    files, ``plan.json`` written whole with the pair and its origin); the two scenario ids."""
    m = plan.mission
    n = new_pair_id(plan)
    ids = [f"pair{n}a", f"pair{n}b"]
    old = next(p for p in plan.pairs if int(p["id"]) == new.replaces)
    keys = set(next(iter(plan.scenarios))["predicted"].get("scores", {})) if plan.scenarios else set()
    origin = {"by": "rapt-plan next", "replaces": new.replaces, "reason": reason, "after_logs": after_logs}
    scenarios = []
    for k, sid in enumerate(ids):
        files = write_scenario_files(m, new.U[k], plan.path.parent, sid)
        scores = {name: float(v) for name, v in zip(names, new.scores[k]) if name in keys}
        scenarios.append(
            {
                "id": sid,
                "u": [float(x) for x in new.U[k]],
                "parameters": jsonable(m.space.decode(new.U[k][None, :])[0]),
                "predicted": {"mode": MODE_NAMES[_mode(new.scores[k])], "scores": scores},
                "files": {kind: path.name for kind, path in files.items()},
                # the day's forecast: its dithers at each noise scale, weighed by the day's outcomes
                "dithering": {"runs": DRAWS * len(SCALES), "p_predicted": float(p_sides[k])},
                "origin": {**origin, "side": "ab"[k]},
            }
        )
    entry = {
        "id": n,
        "level": old.get("level", 0),
        "elements": list(old.get("elements", [])),
        "modes": [MODE_NAMES[_mode(new.scores[k])] for k in range(2)],
        "distance": new.distance,
        "scenarios": ids,
        "refined": False,
        "p_predicted": [float(p) for p in p_sides],
        "p_straddle": float(p_sides[0] * p_sides[1]),
        "origin": origin,
    }
    data = json.loads(plan.path.read_text())
    data["scenarios"].extend(scenarios)
    data["pairs"].append(entry)
    data.setdefault("run_order", []).extend(ids)
    write_text_atomic(plan.path, json.dumps(data, indent=2))
    plan.data = data
    return ids


def _mode(scores: np.ndarray) -> int:
    return int(2 * scores[0] + scores[1])
