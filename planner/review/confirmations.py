"""Which boundaries the day's runs confirmed: each pair side's runs against its predicted outcome.

A pair side is one boundary's side as the plan predicts it: the side scenario's mode and
its values of the pair's score elements (its *outcome*).  The range may fly the scenario
itself, its robust "M" variant, or a variant ``rapt-plan next`` moved during the day; every
run of any of them counts for the side against the side's own predicted outcome, each
scenario's record kept apart (a moved scenario starts its own).  A run whose end is not in
the log tells nothing and is not counted.

The rule is :mod:`rapt.confirmation`'s: a scenario has *shown* its side when
``P(q > 1/2 | its runs) >= 0.75`` under a uniform prior on its per-run chance ``q`` of showing
the outcome (one run that shows; 3 of 4 after a miss), *against* at ``<= 0.25``.  A pair is
confirmed when both its sides have shown and their outcomes differ on the pair's elements.
``rapt-plan compare`` and ``rapt-plan next`` both judge by :func:`confirmation_table`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from planner.common.plans import Plan
from rapt.confirmation import evidence, side_status
from sim.uuv.scoring import mode_name

__all__ = [
    "RunOutcome",
    "pair_elements",
    "outcome_columns",
    "side_scenarios",
    "confirmation_table",
    "boundaries_confirmed",
    "shows",
    "side_summary",
    "target_scores",
    "SIDE_ORDER",
]

#: A side's status from its scenarios' statuses: the first of these any of them has.
SIDE_ORDER = ("shown", "open", "against")


@dataclass(frozen=True)
class RunOutcome:
    """One logged run as the confirmation sees it: its scenario, its scores (None: no end in the log), its log."""

    sid: str
    scores: np.ndarray | None
    log: str = ""


def pair_elements(pair: dict, names: Sequence[str]) -> list[int]:
    """Score columns a pair tests: its elements, and on the root level both root scores (the mode)."""
    cols = [list(names).index(e) for e in pair.get("elements", []) if e in names]
    if not cols or pair.get("level", 0) == 0:
        cols = sorted(set(cols) | {0, 1})
    return cols


def outcome_columns(pair: dict, names: Sequence[str]) -> list[int]:
    """The columns of a side's outcome: the mode's root scores and the pair's elements."""
    return sorted(set(pair_elements(pair, names)) | {0, 1})


def side_scenarios(plan: Plan, sid: str) -> list[str]:
    """The scenarios flown for pair side ``sid``: itself, then its variants in plan order."""
    return [sid] + [v["id"] for v in plan.variants if v.get("variant_of") == sid]


def shows(scores: np.ndarray, cols: Sequence[int], target: Sequence[float] | np.ndarray) -> bool:
    """Whether a run's scores show an outcome: ``target`` on every column of ``cols``."""
    return bool(np.array_equal(np.asarray(scores)[list(cols)], np.asarray(target)))


def side_summary(side: dict) -> str:
    """One side of :func:`confirmation_table` in words: its status, and per scenario flown the runs that showed
    its outcome, e.g. ``shown (pair3bA1 2/3)``."""
    flown = ", ".join(f"{f['scenario']} {f['showed']}/{f['runs']}" for f in side["flown"])
    return f"{side['status']} ({flown})" if flown else side["status"]


def _scenario_record(runs: list[RunOutcome], cols: list[int], target: np.ndarray) -> dict:
    ended = [r for r in runs if r.scores is not None]
    showed = sum(shows(r.scores, cols, target) for r in ended)  # type: ignore[arg-type]
    modes: dict[str, int] = {}
    for r in ended:
        name = mode_name(np.asarray(r.scores))
        modes[name] = modes.get(name, 0) + 1
    missed = len(ended) - showed
    return {
        "runs": len(ended),
        "showed": showed,
        "missed": missed,
        "frequency": showed / len(ended) if ended else None,
        "evidence": evidence(showed, missed) if ended else None,
        "status": side_status(showed, missed) if ended else "unflown",
        "observed_modes": modes,
        "logs": [r.log for r in ended],
    }


def _side_row(plan: Plan, sid: str, cols: list[int], target: np.ndarray, runs: list[RunOutcome]) -> dict:
    flown = []
    for scen in side_scenarios(plan, sid):
        mine = [r for r in runs if r.sid == scen]
        if mine:
            flown.append({"scenario": scen, **_scenario_record(mine, cols, target)})
    statuses = {f["status"] for f in flown}
    status = next((s for s in SIDE_ORDER if s in statuses), "unflown")
    return {
        "scenario": sid,
        "predicted_mode": mode_name(target_scores(cols, target)),
        "runs": sum(f["runs"] for f in flown),
        "showed": sum(f["showed"] for f in flown),
        "status": status,
        "flown": flown,
    }


def target_scores(cols: list[int], target: np.ndarray) -> np.ndarray:
    """A score row holding ``target`` on ``cols`` (enough for :func:`sim.uuv.scoring.mode_name`, root first)."""
    row = np.zeros(max(cols) + 1)
    row[cols] = target
    return row


def confirmation_table(
    plan: Plan, names: Sequence[str], predicted: Mapping[str, np.ndarray], runs: Sequence[RunOutcome]
) -> list[dict]:
    """Per plan pair: each side's runs and status, and the pair's: ``confirmed`` or ``open``.

    ``predicted`` maps each pair side scenario to its predicted score row (the plan's prediction, as the
    pair was chosen); ``runs`` are the day's runs of any plan scenario, repeats included.
    """
    table = []
    for pair in plan.pairs:
        cols = outcome_columns(pair, names)
        elements = pair_elements(pair, names)
        sides = []
        for sid in pair["scenarios"]:
            target = np.asarray(predicted[sid], dtype=float)[cols]
            sides.append(_side_row(plan, sid, cols, target, list(runs)))
        a, b = (np.asarray(predicted[s], dtype=float) for s in pair["scenarios"])
        differ = bool(np.any(a[elements] != b[elements]))
        confirmed = differ and all(s["status"] == "shown" for s in sides)
        row = {
            "id": pair["id"],
            "elements": [names[c] for c in elements],
            "status": "confirmed" if confirmed else "open",
            "sides": sides,
        }
        if "replaces" in pair.get("origin", {}):
            row["replaces"] = pair["origin"]["replaces"]
        table.append(row)
    return table


def boundaries_confirmed(plan: Plan, table: list[dict]) -> int:
    """Boundaries confirmed: the plan's pairs (not those a range day added) confirmed themselves or by a new pair
    ``rapt-plan next`` wrote across the same boundary (``replaces``)."""
    done = {p["id"] for p in table if p["status"] == "confirmed"}
    done |= {p["replaces"] for p in table if p["status"] == "confirmed" and "replaces" in p}
    return sum(p["id"] in done for p in plan.pairs if "origin" not in p)
