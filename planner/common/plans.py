"""A field plan on disk (``plan.json``, schema :data:`PLAN_SCHEMA`): load it, name it, find its scenarios.

``rapt-plan generate`` writes the plan; ``rapt-plan run PLAN --scenario pair1a`` flies one
of its scenarios and ``rapt-plan compare PLAN_DIR LOGS`` reads the logs back against it.
A plan's id is a digest of what makes its runs comparable — the mission's name and every
scenario's and variant's id and unit-cube row — so a log records which plan it flew and a
log of another plan is recognised, even when the plan's files have been copied elsewhere.

A plan carries its mission: ``mission.toml`` is the mission file's text as generated and
``mission.sha256`` its digest, so a plan directory works from anywhere on its own and a
mission edited inside ``plan.json`` afterwards is refused (its scenarios and predictions
were made for the text the digest names).  ``mission.file`` is kept for information.  A
plan written before the mission was embedded still loads from its mission file, found as
given, next to ``plan.json`` or under its name there; regenerating it embeds the mission.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import sim.uuv
from rapt.errors import FileFormatError, InputError, StudyMismatchError
from rapt.space import StateSpace
from sim.uuv.mission import Mission

__all__ = ["Plan", "PLAN_SCHEMA", "load_plan", "plan_id", "coordinate_sensitivity", "embedded_mission"]

#: The schema ``plan.json`` declares (``planner/plan.schema.json``); :func:`load_plan` accepts no other.
PLAN_SCHEMA = "rapt.plan/1"


def plan_id(plan: dict) -> str:
    """12 hex digits naming the plan's mission and scenarios (not its file or timestamps).

    Variants added during the range day (with an ``origin``: ``rapt-plan next``'s moves) are left out, so the
    logs flown before them still belong to the plan.
    """
    rows = [
        (s["id"], [round(float(v), 12) for v in s["u"]])
        for s in list(plan.get("scenarios", [])) + list(plan.get("variants", []))
        if "origin" not in s
    ]
    text = json.dumps({"mission": plan.get("mission", {}).get("name"), "scenarios": rows}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def embedded_mission(text: str) -> dict[str, str]:
    """What ``plan.json`` holds of the mission file's ``text``: the text itself and its sha256."""
    return {"toml": text, "sha256": hashlib.sha256(text.encode("utf-8")).hexdigest()}


@dataclass
class Plan:
    """A loaded plan: its JSON, where it lives, its mission and id.

    ``mission_file`` is the file name the plan was generated from (for information when the
    mission is embedded, the file read otherwise).
    """

    data: dict
    path: Path
    mission: Mission
    mission_file: Path
    id: str

    @property
    def scenarios(self) -> list[dict]:
        """The pair scenarios, in plan order."""
        return list(self.data.get("scenarios", []))

    @property
    def variants(self) -> list[dict]:
        return list(self.data.get("variants", []))

    @property
    def pairs(self) -> list[dict]:
        return list(self.data.get("pairs", []))

    def scenario(self, sid: str | None) -> dict:
        """A scenario or variant by id; InputError listing the ids there are (also when no id is given)."""
        for s in self.scenarios + self.variants:
            if s["id"] == sid:
                return s
        ids = ", ".join(s["id"] for s in self.scenarios + self.variants)
        if sid is None:
            raise InputError(f"--scenario: name the scenario of {self.path} to fly; choose one of {ids}")
        raise InputError(f"--scenario: {sid!r} is not a scenario of {self.path}; choose one of {ids}")

    def u(self, sid: str | None) -> np.ndarray:
        return np.asarray(self.scenario(sid)["u"], dtype=float)

    def sensitivity(self) -> np.ndarray:
        """Per unit-cube coordinate: the summed root-score importance of its parameter."""
        return coordinate_sensitivity(self.mission.space, self.data.get("sensitivity", {}))


def coordinate_sensitivity(space: StateSpace, sensitivity: dict[str, dict[str, float]]) -> np.ndarray:
    """Importance per unit-cube coordinate, summed over the root scores (a parameter's share split evenly).

    ``sensitivity`` maps each root score to its parameters' importances, as ``plan.json`` holds it.
    """
    out = np.zeros(space.dim)
    for root in sensitivity.values():
        for p in space.parameters:
            sl = space.slice_of(p.name)
            out[sl] += float(root.get(p.name, 0.0)) / max(sl.stop - sl.start, 1)
    return out


def load_plan(path: str | Path) -> Plan:
    """``plan.json`` or the directory holding it; ValueError (one line) when it is not a plan."""
    path = Path(path)
    if path.is_dir():
        path = path / "plan.json"
    if not path.is_file():
        raise FileFormatError(
            f"PLAN: {path} does not exist; give a plan directory or plan.json from rapt-plan generate"
        )
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(
            f"PLAN: {path} is not valid JSON ({exc}); regenerate it with rapt-plan generate"
        ) from None
    schema = data.get("schema") if isinstance(data, dict) else None
    if schema != PLAN_SCHEMA:
        raise FileFormatError(
            f"PLAN: {path} is not a {PLAN_SCHEMA} plan (schema {schema!r}); give the plan.json written by rapt-plan generate"
        )
    info = data.get("mission")
    if not isinstance(info, dict):
        raise FileFormatError(f"PLAN: {path}: 'mission' is missing or not an object; regenerate the plan")
    file = Path(str(info.get("file", "")))
    if "toml" in info or "sha256" in info:
        mission = _embedded(path, info)
    else:
        file, mission = _from_file(path, file)
    if mission.name != info.get("name"):
        raise StudyMismatchError(
            f"PLAN: {path}: its mission is {mission.name!r}, but the plan was made for "
            f"{info.get('name')!r}; regenerate the plan from its own mission file"
        )
    return Plan(data, path, mission, file, plan_id(data))


def _embedded(path: Path, info: dict) -> Mission:
    """The mission whose text ``plan.json`` embeds, refused when the text no longer matches its sha256."""
    from sim.uuv.missionfile import load_mission_text

    text, digest = info.get("toml"), info.get("sha256")
    if not isinstance(text, str) or not isinstance(digest, str):
        raise FileFormatError(
            f"PLAN: {path}: mission.toml and mission.sha256 must both be strings; regenerate the plan"
        )
    if embedded_mission(text)["sha256"] != digest:
        raise FileFormatError(
            f"PLAN: {path}: mission.toml was edited after the plan was generated (its sha256 no longer "
            "matches mission.sha256); regenerate the plan from the edited mission with rapt-plan generate"
        )
    return load_mission_text(text, f"{path} mission.toml")


def _from_file(path: Path, file: Path) -> tuple[Path, Mission]:
    """A plan from before the mission was embedded: its mission file, as given or next to ``plan.json``."""
    candidates = [file] if file.is_absolute() else [Path.cwd() / file, path.parent / file, path.parent / file.name]
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise FileFormatError(
            f"PLAN: {path} names mission file {str(file)!r}, which is not there and not embedded (a plan from "
            "before missions were embedded); put the mission file next to plan.json or regenerate the plan"
        )
    return found, sim.uuv.load_mission(found)
