"""The scenarios ``plan.json`` lists, and their robust "M" variants, each with its files written.

Per scenario the plan holds its unit-cube row, its physical parameters, its predicted mode
and scores, its dithering statistics and the names of its files: a QGroundControl
``.plan``, a ``QGC WPL 110`` file and its predicted track as GeoJSON
(:func:`planner.plan.exports.write_scenario_files`, written into the plan directory).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

import sim.uuv
from planner.common.jsonio import jsonable
from planner.plan.analysis import Analysis
from planner.plan.exports import write_scenario_files
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["scenario_entries", "variant_entries", "remove_unlisted"]

#: A file of a plan scenario (pair<k><side>; M for a variant, A<n> for a move rapt-plan next made): only such are removed.
SCENARIO_FILE = re.compile(r"pair\d+[ab](M|A\d+)?\.(plan|waypoints|geojson)")


def scenario_entries(
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


def variant_entries(
    mission: Mission,
    ids: list[str],
    fragile: list[int],
    found: list[dict],
    chosen: sim.uuv.Result,
    out_dir: Path,
) -> list[dict]:
    """The robust "M" variants found for fragile scenarios, their files written."""
    variants = []
    for k, v in zip(fragile, found):
        if not v["found"]:
            continue
        vid = f"{ids[k]}M"
        variants.append(
            {
                "id": vid,
                "variant_of": ids[k],
                "u": v["u"],
                "parameters": jsonable(mission.space.decode(np.array(v["u"])[None, :])[0]),
                "moved": v["moved"],
                "direction": v["direction"],
                "noise_sigmas": v["sigmas"],
                "predicted": {"mode": MODE_NAMES[int(chosen.modes[k])]},
                "p_predicted_mode": v["p_predicted_mode"],
                "p_predicted": v["p_predicted"],
                "files": {
                    kind: path.name
                    for kind, path in write_scenario_files(mission, np.array(v["u"]), out_dir, vid).items()
                },
            }
        )
    return variants


def remove_unlisted(directory: Path, ids: list[str]) -> list[str]:
    """Remove the scenario files in ``directory`` of scenarios the plan does not list (``ids``): a plan made again
    in its directory must not leave an earlier plan's variant beside it for a crew to fly. The names removed."""
    removed = []
    for path in sorted(Path(directory).iterdir()):
        if SCENARIO_FILE.fullmatch(path.name) and path.stem not in ids:
            path.unlink()
            removed.append(path.name)
    return removed
