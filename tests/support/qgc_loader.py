"""QGroundControl's load-time checks of a ``.plan`` and a ``QGC WPL 110`` file, as its loader applies them.

Read from QGroundControl's source: ``PlanMasterController::loadFromFile`` (the file header via
``JsonHelper::validateQGCJsonFile``; ``mission``, ``geoFence`` and ``rallyPoints`` objects all
required), ``MissionController::_loadJsonMissionFileV2`` (mission keys and their types),
``SimpleMissionItem::load`` / ``MissionItem::load`` (item keys, seven ``params``),
``GeoFenceController::load`` and ``QGCFencePolygon::loadFromJson`` (fence v2, polygons v1),
``RallyPointController::load`` (rally v2) and ``MissionController::_loadTextMissionFile`` (WPL).
``JsonHelper::validateKeyTypes`` lets ``null`` stand for a NaN wherever a number is expected.
A fence or rally section of version 1 (or a fence without a version) is not an error in
QGroundControl but is silently dropped; for us that is a lost fence, so it is reported here.

:func:`plan_errors` returns QGroundControl's error for the first rule broken (empty: it loads).
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["plan_errors", "wpl_errors"]

_TYPES = {"Double": (int, float), "String": (str,), "Array": (list,), "Object": (dict,), "Bool": (bool,)}


def _type_ok(value, kind: str) -> bool:
    if kind == "Double":
        return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))
    return isinstance(value, _TYPES[kind])


def _keys(obj: dict, info: list[tuple[str, str, bool]]) -> str | None:
    """``JsonHelper::validateKeys``: required keys present, every listed key of its type."""
    missing = [k for k, _, required in info if required and k not in obj]
    if missing:
        return f"The following required keys are missing: {', '.join(missing)}"
    for key, kind, _ in info:
        if key in obj and not _type_ok(obj[key], kind):
            return f"Incorrect value type - key:type:expected {key}:{type(obj[key]).__name__}:{kind}"
    return None


def _coordinate(value, altitude: bool) -> str | None:
    """``JsonHelper::loadGeoCoordinate``: [lat, lon(, alt)] of numbers or nulls."""
    if not isinstance(value, list):
        return "value for coordinate is not array"
    n = 3 if altitude else 2
    if len(value) != n:
        return f"Coordinate array must contain {n} values"
    if not all(_type_ok(v, "Double") for v in value):
        return "Coordinate array may only contain double values"
    return None


def _item(i: int, item) -> str | None:
    if not isinstance(item, dict):
        return f"Mission item {i} is not an object"
    if err := _keys(item, [("type", "String", True)]):
        return err
    if item["type"] != "SimpleItem":  # our files hold no complex items
        return f"Unknown item type: {item['type']}"
    info = [
        ("type", "String", True),
        ("frame", "Double", True),
        ("command", "Double", True),
        ("params", "Array", True),
        ("autoContinue", "Bool", True),
        ("doJumpId", "Double", False),
    ]
    if err := _keys(item, info):
        return err
    if len(item["params"]) != 7:
        return "params key must contains 7 values"
    for k, p in enumerate(item["params"], start=1):
        if not _type_ok(p, "Double"):
            return f"Param {k} incorrect type, must be double or null"
    altitude_keys = ("AltitudeMode", "Altitude", "AMSLAltAboveTerrain")
    if any(k in item for k in altitude_keys):
        return _keys(item, [(k, "Double", True) for k in altitude_keys])
    return None


def _mission(m: dict) -> str | None:
    info = [
        ("plannedHomePosition", "Array", True),
        ("items", "Array", True),
        ("firmwareType", "Double", True),
        ("vehicleType", "Double", False),
        ("cruiseSpeed", "Double", False),
        ("hoverSpeed", "Double", False),
        ("globalPlanAltitudeMode", "Double", False),
    ]
    if err := _keys(m, info):
        return err
    if err := _coordinate(m["plannedHomePosition"], altitude=True):
        return err
    for i, item in enumerate(m["items"]):
        if err := _item(i, item):
            return err
    return None


def _fence(f: dict) -> str | None:
    if "version" not in f or f["version"] == 1:
        return "version 1 or none: QGroundControl ignores this fence without a word"
    info = [("version", "Double", True), ("circles", "Array", True), ("polygons", "Array", True)]
    if err := _keys(f, info + [("breachReturn", "Array", False)]):
        return err
    if f["version"] != 2:
        return "GeoFence supports version 2"
    for p in f["polygons"]:
        if not isinstance(p, dict):
            return "GeoFence polygon not stored as object"
        if err := _keys(p, [("version", "Double", True), ("inclusion", "Bool", True), ("polygon", "Array", True)]):
            return err
        if p["version"] != 1:
            return "GeoFence Polygon only supports version 1"
        for v in p["polygon"]:
            if err := _coordinate(v, altitude=False):
                return err
    for c in f["circles"]:
        if not isinstance(c, dict):
            return "GeoFence circle not stored as object"
    if "breachReturn" in f:
        return _coordinate(f["breachReturn"], altitude=True)
    return None


def _rally(r: dict) -> str | None:
    if r.get("version") == 1:
        return "version 1: QGroundControl ignores these rally points without a word"
    if err := _keys(r, [("version", "Double", True), ("points", "Array", True)]):
        return err
    if r["version"] != 2:
        return "Rally Points supports version 2"
    for p in r["points"]:
        if err := _coordinate(p, altitude=True):
            return err
    return None


def plan_errors(path: Path) -> list[str]:
    """QGroundControl's complaint about the ``.plan`` at ``path`` (its first), or [] when it loads."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        return [f"not JSON: {exc}"]
    if not isinstance(doc, dict):
        return ["not a JSON object"]
    if err := _keys(
        doc, [("fileType", "String", True), ("groundStation", "String", True), ("version", "Double", True)]
    ):
        return [err]
    if doc["fileType"] != "Plan":
        return [f"Incorrect file type key expected:Plan actual:{doc['fileType']}"]
    version = doc["version"]
    if not (isinstance(version, int) and not isinstance(version, bool)) or version != 1:
        return [f"File version {version} is not the supported version 1"]
    sections = [("mission", "Object", True), ("geoFence", "Object", True), ("rallyPoints", "Object", True)]
    if err := _keys(doc, sections):
        return [err]
    for label, key, check in (
        ("Mission", "mission", _mission),
        ("GeoFence", "geoFence", _fence),
        ("Rally", "rallyPoints", _rally),
    ):
        if err := check(doc[key]):
            return [f"{label}: {err}"]
    return []


def wpl_errors(path: Path) -> list[str]:
    """``MissionController::_loadTextMissionFile``: the header, then 12 tab-separated fields a line."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    if not lines or lines[0].split(" ") != ["QGC", "WPL", "110"]:
        return ["The mission file is not compatible with this version of QGroundControl."]
    for n, line in enumerate(lines[1:], start=2):
        if len(line.split("\t")) != 12:
            return [f"line {n}: The mission file is corrupted."]
    return []
