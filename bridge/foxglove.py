"""Foxglove's well-known messages derived from the bus, so Foxglove's panels show a log unconfigured.

Foxglove draws a channel in its Map, Log and 3D panels when the channel's schema is one of
its well-known schemas. Those schemas and their encoder come from Foxglove's own Python SDK
(``foxglove-sdk``, :mod:`foxglove.messages`): each message is written as Protobuf under the
SDK's ``FileDescriptorSet``, the encoding Foxglove's own SDK logs them in, so the log, the live
view (:mod:`bridge.live_view`) and Foxglove agree on every field. :class:`FoxgloveMessages`
turns what the bus carries into these messages (as plain dicts with Foxglove's field names;
:func:`encode` makes the wire bytes), next to the logger's own channels (which stay JSON):

=======================  ==========================  =================================================
topic                    schema                      from
=======================  ==========================  =================================================
``/vehicle/fix``         ``foxglove.LocationFix``    ``mavlink/GLOBAL_POSITION_INT`` (degE7 -> deg, mm -> m)
``/vehicle/log``         ``foxglove.Log``            ``mavlink/STATUSTEXT`` and the autonomy's events
                                                     (``status/bringup|watchdog|referee``, changes of
                                                     the back-seat's goal and return reason)
``/vehicle/tf``          ``foxglove.FrameTransform`` ``mavlink/LOCAL_POSITION_NED`` + ``ATTITUDE``'s yaw
``/vehicle/track_local`` ``foxglove.PosesInFrame``   the same poses, a trail of at most
                                                     :data:`MAX_TRAIL` (thinned as it grows)
``/map/<name>``          ``foxglove.GeoJSON``        ``map/<name>``: a GeoJSON document (mission
                                                     elements, predicted track), written once
=======================  ==========================  =================================================

The local frame :data:`LOCAL_FRAME` is ENU (x east, y north, z up) as Foxglove's 3D panel
expects; MAVLink's NED position and yaw are turned into it. Timestamps are the bridge's
receive time (``_recv_ns``), the log time of the message they come from.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

from foxglove import Schema
from foxglove import messages as fox

from bridge import keys

__all__ = [
    "WELL_KNOWN",
    "ENCODING",
    "FIX_TOPIC",
    "LOG_TOPIC",
    "TF_TOPIC",
    "TRAIL_TOPIC",
    "LOCAL_FRAME",
    "VEHICLE_FRAME",
    "MAX_TRAIL",
    "schema",
    "encode",
    "map_topic",
    "stamp",
    "location_fix",
    "geojson_message",
    "log_message",
    "FoxgloveMessages",
]

FIX_TOPIC = "/vehicle/fix"
LOG_TOPIC = "/vehicle/log"
TF_TOPIC = "/vehicle/tf"
TRAIL_TOPIC = "/vehicle/track_local"
LOCAL_FRAME = "local"
VEHICLE_FRAME = "vehicle"
#: The message encoding of every Foxglove channel (the SDK's schemas are Protobuf descriptors).
ENCODING = "protobuf"
#: Poses kept in the local-frame trail; beyond it every other pose is dropped and the spacing doubles.
MAX_TRAIL = 100
#: Vehicle time between two poses of the trail at first (ms).
TRAIL_SPACING_MS = 1000

# foxglove.LogLevel
DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5
#: MAV_SEVERITY (0 EMERGENCY ... 7 DEBUG) -> foxglove.LogLevel.
SEVERITY_LEVEL = {0: FATAL, 1: FATAL, 2: FATAL, 3: ERROR, 4: WARNING, 5: INFO, 6: INFO, 7: DEBUG}
#: The back-seat's goal kinds and return reasons (sim.uuv.autonomy's GOAL_* and RETURN_*; bridge cannot import sim).
GOALS = {0: "waypoint", 1: "transmit", 2: "survey", 3: "return"}
RETURN_REASONS = {0: "none", 1: "mission complete", 2: "battery", 3: "time limit"}
BRINGUP_LEVEL = {"failed": ERROR, "fallback": WARNING}
WATCHDOG_LEVEL = {"intervention": ERROR, "violation": WARNING}

Derived = tuple[str, str, dict]  # (topic, schema name, message)

_LEVELS = {
    int(v.value): v
    for v in (
        fox.LogLevel.Debug,
        fox.LogLevel.Info,
        fox.LogLevel.Warning,
        fox.LogLevel.Error,
        fox.LogLevel.Fatal,
        fox.LogLevel.Unknown,
    )
}
_COVARIANCE_TYPES = {
    int(v.value): v
    for v in (
        fox.LocationFixPositionCovarianceType.Unknown,
        fox.LocationFixPositionCovarianceType.Approximated,
        fox.LocationFixPositionCovarianceType.DiagonalKnown,
        fox.LocationFixPositionCovarianceType.Known,
    )
}


def _time(t: dict) -> Any:
    return fox.Timestamp(int(t["sec"]), int(t["nsec"]))


def _pose_of(p: dict) -> Any:
    q, r = p["position"], p["orientation"]
    return fox.Pose(position=fox.Vector3(x=q["x"], y=q["y"], z=q["z"]), orientation=fox.Quaternion(**r))


#: Schema name -> (the SDK's message class, its constructor from our dict).
_SDK: dict[str, tuple[Any, Callable[[dict], Any]]] = {
    "foxglove.LocationFix": (
        fox.LocationFix,
        lambda m: fox.LocationFix(
            timestamp=_time(m["timestamp"]),
            frame_id=m["frame_id"],
            latitude=m["latitude"],
            longitude=m["longitude"],
            altitude=m["altitude"],
            position_covariance=list(m["position_covariance"]),
            position_covariance_type=_COVARIANCE_TYPES[int(m["position_covariance_type"])],
        ),
    ),
    "foxglove.Log": (
        fox.Log,
        lambda m: fox.Log(
            timestamp=_time(m["timestamp"]),
            level=_LEVELS[int(m["level"])],
            message=m["message"],
            name=m["name"],
            file=m["file"],
            line=int(m["line"]),
        ),
    ),
    "foxglove.FrameTransform": (
        fox.FrameTransform,
        lambda m: fox.FrameTransform(
            timestamp=_time(m["timestamp"]),
            parent_frame_id=m["parent_frame_id"],
            child_frame_id=m["child_frame_id"],
            translation=fox.Vector3(**m["translation"]),
            rotation=fox.Quaternion(**m["rotation"]),
        ),
    ),
    "foxglove.PosesInFrame": (
        fox.PosesInFrame,
        lambda m: fox.PosesInFrame(
            timestamp=_time(m["timestamp"]), frame_id=m["frame_id"], poses=[_pose_of(p) for p in m["poses"]]
        ),
    ),
    "foxglove.GeoJSON": (fox.GeoJson, lambda m: fox.GeoJson(geojson=m["geojson"])),
}
#: The Foxglove schemas the logs use.
WELL_KNOWN = tuple(_SDK)


def schema(name: str) -> Schema:
    """The SDK's schema of Foxglove's well-known ``name`` (e.g. ``"foxglove.LocationFix"``): ``.name``,
    ``.encoding`` (``"protobuf"``) and ``.data`` (its ``FileDescriptorSet``)."""
    if name not in _SDK:
        raise ValueError(f"schema: {name!r} is not one of {', '.join(WELL_KNOWN)}")
    return _SDK[name][0].get_schema()


def encode(name: str, message: dict) -> bytes:
    """``message`` (a dict with the fields of Foxglove's ``name``) as the SDK encodes it."""
    if name not in _SDK:
        raise ValueError(f"encode: {name!r} is not one of {', '.join(WELL_KNOWN)}")
    return _SDK[name][1](message).encode()


def map_topic(name: str) -> str:
    """``/map/<name>``: the topic of the bus's ``map/<name>`` GeoJSON document."""
    return f"/map/{name}"


def stamp(ns: int) -> dict[str, int]:
    """A Foxglove ``time`` ({sec, nsec}) from nanoseconds since the epoch."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def location_fix(lat: float, lon: float, alt: float, ns: int, frame_id: str = VEHICLE_FRAME) -> dict:
    """A ``foxglove.LocationFix`` (degrees, metres); covariance unknown."""
    return {
        "timestamp": stamp(ns),
        "frame_id": frame_id,
        "latitude": float(lat),
        "longitude": float(lon),
        "altitude": float(alt),
        "position_covariance": [0.0] * 9,
        "position_covariance_type": 0,
    }


def geojson_message(document: Any) -> dict:
    """A ``foxglove.GeoJSON`` holding ``document`` (a GeoJSON object) as its string."""
    return {"geojson": json.dumps(document, allow_nan=False)}


def log_message(level: int, message: str, name: str, ns: int) -> dict:
    """A ``foxglove.Log`` line from process ``name``."""
    return {"timestamp": stamp(ns), "level": int(level), "message": message, "name": name, "file": "", "line": 0}


def _pose(x: float, y: float, z: float, yaw: float) -> dict:
    """A pose in :data:`LOCAL_FRAME` (ENU) from a NED position and yaw (rad, clockwise from north), to 1 mm
    and 1e-5 (the MAVLink channels keep the full values; this keeps the trail small)."""
    heading = math.pi / 2 - yaw  # counter-clockwise from east
    return {
        "position": {"x": round(y, 3), "y": round(x, 3), "z": round(-z, 3)},
        "orientation": {"x": 0.0, "y": 0.0, "z": round(math.sin(heading / 2), 5), "w": round(math.cos(heading / 2), 5)},
    }


def _named(names: dict[int, str], value: Any) -> str:
    """The name of code ``value`` in ``names``, or the value itself as text."""
    return names.get(value, str(value)) if isinstance(value, int) else str(value)


def _number(obj: dict, key: str) -> float | None:
    v = obj.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


class FoxgloveMessages:
    """Derive Foxglove messages from one vehicle's bus samples, in the order they are logged (one thread).

    Keeps what a message needs from earlier ones: the last yaw, the local trail, and the
    back-seat's last goal and return reason (its events are their changes).
    """

    def __init__(self) -> None:
        self._yaw = 0.0
        self._trail: list[dict] = []
        self._trail_ms: int | None = None
        self._spacing_ms = TRAIL_SPACING_MS
        self._autonomy: dict[str, tuple] = {}

    def derive(self, kind: str, name: str, obj: Any, ns: int) -> list[Derived]:
        """The Foxglove messages sample ``rapt/<v>/<kind>/<name>`` (JSON ``obj``, time ``ns``) gives; often none."""
        if not isinstance(obj, dict):
            return []
        if kind == "map":
            return [(map_topic(name), "foxglove.GeoJSON", geojson_message(obj))]
        if kind == "mavlink":
            handler = {
                "GLOBAL_POSITION_INT": self._fix,
                "STATUSTEXT": self._statustext,
                "ATTITUDE": self._attitude,
                "LOCAL_POSITION_NED": self._local,
            }.get(name)
            return handler(obj, ns) if handler is not None else []
        if kind == "status":
            line = self._event(name, obj)
            return [] if line is None else [(LOG_TOPIC, "foxglove.Log", log_message(line[0], line[1], name, ns))]
        return []

    # -- MAVLink ---------------------------------------------------------------------
    def _fix(self, obj: dict, ns: int) -> list[Derived]:
        lat, lon, alt = _number(obj, "lat"), _number(obj, "lon"), _number(obj, "alt")
        if lat is None or lon is None or alt is None:
            return []
        return [(FIX_TOPIC, "foxglove.LocationFix", location_fix(lat / 1e7, lon / 1e7, alt / 1000.0, ns))]

    def _statustext(self, obj: dict, ns: int) -> list[Derived]:
        text = obj.get("text")
        if not isinstance(text, str):
            return []
        severity = _number(obj, "severity")
        level = INFO if severity is None else SEVERITY_LEVEL.get(int(severity), INFO)
        return [(LOG_TOPIC, "foxglove.Log", log_message(level, text.rstrip("\x00"), "vehicle", ns))]

    def _attitude(self, obj: dict, ns: int) -> list[Derived]:
        yaw = _number(obj, "yaw")
        if yaw is not None:
            self._yaw = yaw
        return []

    def _local(self, obj: dict, ns: int) -> list[Derived]:
        x, y, z = _number(obj, "x"), _number(obj, "y"), _number(obj, "z")
        if x is None or y is None or z is None:
            return []
        pose = _pose(x, y, z, self._yaw)
        tf = {
            "timestamp": stamp(ns),
            "parent_frame_id": LOCAL_FRAME,
            "child_frame_id": VEHICLE_FRAME,
            "translation": pose["position"],
            "rotation": pose["orientation"],
        }
        out = [(TF_TOPIC, "foxglove.FrameTransform", tf)]
        t_ms = obj.get("time_boot_ms")
        t_ms = int(t_ms) if isinstance(t_ms, int) else ns // 1_000_000
        if self._trail_ms is None or t_ms - self._trail_ms >= self._spacing_ms or t_ms < self._trail_ms:
            self._trail.append(pose)
            self._trail_ms = t_ms
            if len(self._trail) > MAX_TRAIL:  # thin it: the whole run stays in view at a bounded size
                self._trail = self._trail[::2]
                self._spacing_ms *= 2
            trail = {"timestamp": stamp(ns), "frame_id": LOCAL_FRAME, "poses": list(self._trail)}
            out.append((TRAIL_TOPIC, "foxglove.PosesInFrame", trail))
        return out

    # -- the autonomy's events -------------------------------------------------------------
    def _event(self, source: str, obj: dict) -> tuple[int, str] | None:
        """(level, text) of a back-seat process's status, or None when it reports no event."""
        if source == keys.BRINGUP_SOURCE and "name" in obj and "status" in obj:
            detail = f": {obj['detail']}" if obj.get("detail") else ""
            return BRINGUP_LEVEL.get(str(obj["status"]), INFO), f"bring-up {obj['name']} {obj['status']}{detail}"
        if source == "referee" and obj.get("ended"):
            return INFO, f"run ended: {obj['ended']}"
        if "event" in obj:  # the watchdog's violations, interventions and mode changes
            rest = ", ".join(f"{k}={v}" for k, v in obj.items() if k not in ("event", "time_boot_ms") and v is not None)
            return WATCHDOG_LEVEL.get(str(obj["event"]), INFO), f"{obj['event']}: {rest}"
        if "goal" in obj:  # the back-seat's status, every decision: report its changes only
            state = (obj.get("goal"), obj.get("return_reason"), tuple(obj.get("wp_aborted") or ()))
            before = self._autonomy.get(source)
            self._autonomy[source] = state
            if before == state:
                return None
            goal, reason, aborted = state
            text = f"goal: {_named(GOALS, goal)}"
            if reason:
                text += f" (returning: {_named(RETURN_REASONS, reason)})"
            if any(aborted):
                text += f"; waypoints aborted: {[i for i, a in enumerate(aborted) if a]}"
            return (WARNING if any(aborted) and before is not None and aborted != before[2] else INFO), text
        return None
