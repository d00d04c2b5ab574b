"""A side that came out against its prediction, moved: a new variant that shows the side's outcome in the day's water.

The move is the plan's own search for robust variants (:func:`planner.plan.dithering.robust_variants`:
steps of the execution noise away from the partner, up the dithers' gradient or along the most
sensitive parameters, until the dithers hold the outcome), run on the mission as the afternoon
knows it (the noon's bias and the afternoon's on top) with the noise fitted to the day's outcomes.
A move found becomes a plan variant only when ``rapt-plan next`` chooses it (:func:`add_variant`):
its range files are written beside the plan's, and ``plan.json`` gains it with its origin, written
whole, so ``rapt-plan run`` flies it and ``rapt-plan compare`` knows its logs.  Variants with an
origin do not change the plan's id (:func:`planner.common.plans.plan_id`): the logs flown before
still belong to the plan.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

import sim.uuv
from planner.common.atomic import write_text_atomic
from planner.common.jsonio import jsonable
from planner.common.plans import Plan
from planner.plan.dithering import Outcome, robust_variants
from planner.plan.exports import write_scenario_files
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["Move", "find_move", "add_variant", "variant_id", "MOVE_TARGET"]

#: A move must hold its side's outcome in this share of its dithers (the plan's own target for variants).
MOVE_TARGET = 0.8
#: Dithers screening each candidate move, and confirming the best.
SCREEN, CONFIRM = 16, 48


@dataclass
class Move:
    """A candidate variant of pair side ``side``: its row and how it was moved from the scenario it replaces."""

    side: str
    moved_from: str
    u: np.ndarray
    p: float
    parameter: str
    unit_step: float
    sigmas: float
    direction: str


def find_move(
    mission: Mission,
    plan_mission: Mission,
    side: str,
    moved_from: tuple[str, np.ndarray],
    partner: np.ndarray,
    outcome: Outcome,
    dithers: tuple[np.ndarray, np.ndarray],
    sensitivity: np.ndarray,
    sigma: np.ndarray,
    seed: int,
) -> Move | None:
    """The smallest move of ``moved_from`` that holds ``outcome`` at :data:`MOVE_TARGET` in the day's ``mission``
    (None: none does, or the one found is not a valid run of the plan's mission, which the plan must predict)."""
    sid, u = moved_from
    found, _ = robust_variants(
        mission,
        u[None, :],
        partner[None, :],
        [outcome],
        [dithers],
        sensitivity,
        sigma,
        SCREEN,
        CONFIRM,
        MOVE_TARGET,
        seed,
    )
    v = found[0]
    if not v["found"] or not sim.uuv.simulate(plan_mission, np.asarray(v["u"], dtype=float)[None, :]).valid[0]:
        return None
    return Move(
        side,
        sid,
        np.asarray(v["u"], dtype=float),
        float(v["p_predicted"]),
        v["moved"]["parameter"],
        float(v["moved"]["unit_step"]),
        float(v["sigmas"]),
        v["direction"],
    )


def variant_id(plan: Plan, side: str) -> str:
    """The next free id of a variant of ``side`` moved during the day: ``<side>A1``, ``<side>A2``..."""
    taken = {s["id"] for s in plan.scenarios + plan.variants}
    n = 1
    while f"{side}A{n}" in taken:
        n += 1
    return f"{side}A{n}"


def add_variant(plan: Plan, move: Move, vid: str, reason: str, after_logs: list[str], bias: dict) -> None:
    """Write ``move`` into the plan as variant ``vid``: its range files, then ``plan.json`` with it and its origin."""
    m = plan.mission
    directory = plan.path.parent
    mode = MODE_NAMES[int(sim.uuv.simulate(m, move.u[None, :]).modes[0])]  # valid: find_move checked
    files = write_scenario_files(m, move.u, directory, vid)
    entry = {
        "id": vid,
        "variant_of": move.side,
        "u": [float(x) for x in move.u],
        "parameters": jsonable(m.space.decode(move.u[None, :])[0]),
        "moved": {"parameter": move.parameter, "unit_step": move.unit_step},
        "direction": move.direction,
        "noise_sigmas": move.sigmas,
        "predicted": {"mode": mode},
        "p_predicted_mode": move.p,
        "p_predicted": move.p,
        "files": {kind: path.name for kind, path in files.items()},
        "origin": {
            "by": "rapt-plan next",
            "moved_from": move.moved_from,
            "reason": reason,
            "after_logs": after_logs,
            "bias": bias,
        },
    }
    data = json.loads(plan.path.read_text())
    data.setdefault("variants", []).append(entry)
    data.setdefault("run_order", []).append(vid)
    write_text_atomic(plan.path, json.dumps(data, indent=2))
    plan.data = data
