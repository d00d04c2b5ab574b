"""Mission files: a TOML description of a range day, loaded into a :class:`sim.uuv.mission.Mission`.

:func:`load_mission` reads and checks the whole file; every problem is a
:class:`MissionFileError` of ONE line naming the file, the field and the fix, e.g.::

    examples/x.toml: parameters[3].target: unknown element 'nogo.Z' (known no-go areas: N1); name an element defined in [[nogo]]

Positions are metres in the local frame of the origin (x east, y north; :mod:`sim.uuv.geo`),
times are seconds, sizes are full widths/heights of axis-aligned rectangles around their
centre.  Keys marked ``=value`` are optional with that default; the others are required.

.. code-block:: toml

    [mission]
    name = "uuv18"
    origin = { lat = 47.70, lon = -122.62 }   # degrees, WGS84
    start_time_s = 21600          # seconds after local midnight (sets the tide); default when not a parameter
    time_limit_s = 14400
    waypoint_radius_m = 25.0      # =25
    dt_s = 2.0                    # =2, simulation step
    priority = ["A", "B", "C"]    # =file order of [[mission_areas]]; a permutation of their names
    requires = ["mission_areas", "transmission", "mission_time"]
        # -> Mission.mission_requires: the level-2 mission objectives mission success needs,
        #    from waypoints, mission_areas, transmission, mission_time; default: the last
        #    three (those the mission has)

    [operational_area]            # x, y (centre), width, height
    [launch]                      # x, y
    [recovery]                    # x, y, radius_m=15
    [[waypoints]]                 # x, y  (named "0", "1", ... in score names)
    [[mission_areas]]             # name, x, y, width=500, height=500, dwell_s
    [transmission]                # optional: name="transmission", x, y, width=700, height=750,
                                  #   window_start_s=1800, window_length_s=3600, duration_s=120
    [[nogo]]                      # name, x, y, width=400, height=500
    [[barriers]]                  # name, x, y, width=40, height=700
    [[obstacles]]                 # name, x, y, side=50  (equilateral triangle)
    [vehicle]                     # optional overrides of sim.uuv.mission.Vehicle fields, e.g.
                                  #   speed_gain=1: through-water speed reached per unit commanded
                                  #   (at most max_speed); rapt-plan calibrate fits it from logs
    [current]                     # optional overrides of sim.uuv.mission.Current fields

    [[parameters]]                # one per state-space parameter, in state-space order
    name = "nogo_x"
    kind = "continuous"           # continuous | integer | categorical | permutation
    low = 200.0                   # continuous/integer: low < high (log=false, continuous only)
    high = 1300.0                 # categorical: choices = [...]; permutation: items = [...]
    target = "nogo.N1.x"

    [score_tree]                  # the root node
    name = "root"
    scores = ["mission_success", "safety_success"]
    [[score_tree.children]]
    name = "waypoints"
    scores = ["waypoints"]
    [[score_tree.children.children]]
    for_each = "waypoint"         # one copy per waypoint, {name} -> "0", "1", ...
    name = "waypoint {name}"
    scores = ["waypoint.{name}"]
    [[score_tree.children.children.children]]
    name = "waypoint {name} metrics"
    scores = ["waypoint.{name}.closest_m", "waypoint.{name}.time_s", "waypoint.{name}.battery",
              "waypoint.{name}.aborted"]

Element names (mission areas, transmission, no-go areas, barriers, obstacles) use letters,
digits, ``_`` and ``-`` and are unique across the file.  Every element centre lies in
the operational area.

**Parameters.**  ``target`` is ``"<kind>.<field>"`` for ``mission.start_time_s``,
``vehicle.start_battery``, ``mission_areas.priority`` and ``transmission.<field>``, and
``"<kind>.<element name>.<field>"`` for ``nogo``, ``barrier``, ``obstacle`` and
``mission_area`` (fields: :data:`sim.uuv.mission.TARGET_FIELDS`).  ``mission_areas.priority``
must be a permutation whose items are exactly the mission-area names; every other target
takes a continuous, integer or numeric categorical parameter.  The range of an ``x``/``y``
parameter lies inside the operational area, ``start_time_s`` within a day,
``start_battery`` within [0, 1], window and dwell times are not negative.  The loader
builds ``Mission.space`` (a :class:`rapt.StateSpace`, file order) and ``Mission.bindings``
(one :class:`sim.uuv.mission.Binding` per parameter; ``name`` is ``None`` for targets without
an element name).  The fixed values in the element tables stay the nominal scenario.

**Score tree.**  Nodes mirror rapt's ``{"name", "indices", "children"}`` mapping but list
metric NAMES (:func:`sim.uuv.metrics.metric_names`) in ``scores``.  A node has ``scores``
(required), ``name`` (default: its first score), ``children`` (``[[...children]]``) and
``for_each`` (one of :data:`sim.uuv.metrics.ELEMENT_KINDS`: waypoint, area, obstacle,
barrier, nogo), which replicates the node once per element of that kind, substituting
``{name}`` in its own and its descendants' names and scores (a nested ``for_each``
rebinds it).  A node replicated over zero elements disappears.  Every score column must
appear in exactly one node.  The resolved mapping (column indices) is
``Mission.score_tree``.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from rapt.errors import FileFormatError
from rapt.scoretree import ScoreTree
from rapt.space import Categorical, Continuous, Integer, Parameter, Permutation, StateSpace
from sim.uuv.metrics import ELEMENT_KINDS, element_names, metric_names
from sim.uuv.mission import TARGET_FIELDS, Binding, Current, Mission, MissionArea, Rect, Transmission, Triangle, Vehicle

__all__ = ["load_mission", "load_mission_text", "MissionFileError"]


class MissionFileError(FileFormatError):
    """A mission file that cannot be loaded; the message is one line: file, field, problem, fix.

    A :class:`rapt.errors.FileFormatError`, so also an ``InputError``, a ``RaptError`` and a ``ValueError``.
    """


_MISSING = object()
_NAME_RE = re.compile(r"^[A-Za-z0-9_-]+$")

_SECTIONS = (
    "mission",
    "operational_area",
    "launch",
    "recovery",
    "waypoints",
    "mission_areas",
    "transmission",
    "nogo",
    "barriers",
    "obstacles",
    "vehicle",
    "current",
    "parameters",
    "score_tree",
)
_REQUIRED_SECTIONS = ("mission", "operational_area", "launch", "recovery", "parameters", "score_tree")
_ARRAY_SECTIONS = ("waypoints", "mission_areas", "nogo", "barriers", "obstacles", "parameters")
_REQUIRES = ("waypoints", "mission_areas", "transmission", "mission_time")
_PARAM_KINDS = ("continuous", "integer", "categorical", "permutation")
_PARAM_KEYS = {
    "continuous": (("name", "kind", "target", "low", "high"), ("log",)),
    "integer": (("name", "kind", "target", "low", "high"), ()),
    "categorical": (("name", "kind", "target", "choices"), ()),
    "permutation": (("name", "kind", "target", "items"), ()),
}
#: Target kinds written without an element name.
_UNNAMED_TARGETS = ("mission", "vehicle", "mission_areas", "transmission")
#: Target kind -> (file section, words for its elements).
_NAMED_TARGETS = {
    "nogo": ("nogo", "no-go areas"),
    "barrier": ("barriers", "barriers"),
    "obstacle": ("obstacles", "obstacles"),
    "mission_area": ("mission_areas", "mission areas"),
}


def load_mission(path: str | Path) -> Mission:
    """Read, check and build the mission in the TOML file ``path``."""
    return _Loader(str(path)).load(Path(path))


def load_mission_text(text: str, label: str) -> Mission:
    """Check and build the mission in TOML ``text`` (e.g. the copy a field plan embeds).

    ``label`` names where the text came from, in errors and as the mission's ``source``.
    """
    return _Loader(label).load_text(text)


def _fmt(v: float) -> str:
    return f"{v:g}"


def _names(items) -> str:
    items = list(items)
    return ", ".join(map(str, items)) if items else "none"


class _Loader:
    def __init__(self, label: str):
        self.label = label

    # ------------------------------------------------------------------ errors and primitives
    def fail(self, where: str, message: str) -> NoReturn:
        message = " ".join(str(message).split())  # one line, always
        raise MissionFileError(f"{self.label}: {where}: {message}")

    def table(self, value: Any, where: str, header: str) -> dict:
        if not isinstance(value, dict):
            self.fail(where, f"expected a table, got {type(value).__name__} {value!r}; write it as {header}")
        return value

    def keys(self, tbl: Mapping, where: str, required=(), optional=()) -> None:
        allowed = tuple(required) + tuple(optional)
        for key in tbl:
            if key not in allowed:
                hint = difflib.get_close_matches(key, allowed, n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                self.fail(f"{where}.{key}" if where else key, f"unknown key{did}; allowed keys: {_names(allowed)}")
        for key in required:
            if key not in tbl:
                self.fail(
                    f"{where}.{key}" if where else key,
                    f"missing required key; add {key} = ... to {where or 'the file'}",
                )

    def number(
        self,
        tbl: Mapping,
        key: str,
        where: str,
        default: Any = _MISSING,
        *,
        low: float | None = None,
        high: float | None = None,
        positive: bool = False,
    ) -> float:
        field = f"{where}.{key}"
        if key not in tbl:
            if default is _MISSING:
                self.fail(field, f"missing required number; add {key} = <number> to {where}")
            return default
        return self.check_number(tbl[key], field, low=low, high=high, positive=positive)

    def check_number(
        self, v: Any, field: str, *, low: float | None = None, high: float | None = None, positive: bool = False
    ) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(field, f"expected a number, got {type(v).__name__} {v!r}; write a plain number such as 10.0")
        v = float(v)
        if not math.isfinite(v):
            self.fail(field, f"{v} is not finite; give a finite number")
        if positive and v <= 0:
            self.fail(field, f"{_fmt(v)} must be > 0; give a positive number")
        if low is not None and v < low:
            self.fail(
                field,
                f"{_fmt(v)} is below the minimum {_fmt(low)}; use a value in [{_fmt(low)}, {_fmt(high) if high is not None else 'inf'}]",
            )
        if high is not None and v > high:
            self.fail(
                field,
                f"{_fmt(v)} is above the maximum {_fmt(high)}; use a value in [{_fmt(low) if low is not None else '-inf'}, {_fmt(high)}]",
            )
        return v

    def string(self, tbl: Mapping, key: str, where: str, default: Any = _MISSING) -> str:
        field = f"{where}.{key}"
        if key not in tbl:
            if default is _MISSING:
                self.fail(field, f'missing required string; add {key} = "..." to {where}')
            return default
        v = tbl[key]
        if not isinstance(v, str) or not v:
            self.fail(field, f'expected a non-empty string, got {v!r}; write {key} = "..."')
        return v

    def element_name(self, tbl: Mapping, where: str, default: Any = _MISSING) -> str:
        name = self.string(tbl, "name", where, default)
        if not _NAME_RE.match(name):
            self.fail(f"{where}.name", f"{name!r} is not a valid element name; use letters, digits, '_' or '-' only")
        if name in self.element_owner:
            self.fail(
                f"{where}.name",
                f"duplicate element name {name!r} (already used by {self.element_owner[name]}); "
                "give every element its own name",
            )
        self.element_owner[name] = where
        return name

    def string_list(self, v: Any, field: str) -> list[str]:
        if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
            self.fail(field, f'expected a list of strings, got {v!r}; write e.g. ["A", "B"]')
        return v

    def inside(self, x: float, y: float, field: str, what: str = "centre") -> None:
        op = self.op
        x0, x1, y0, y1 = op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            self.fail(
                field,
                f"{what} (x={_fmt(x)}, y={_fmt(y)}) lies outside the operational area "
                f"(x {_fmt(x0)}..{_fmt(x1)}, y {_fmt(y0)}..{_fmt(y1)}); move it inside",
            )

    def array(self, data: Mapping, key: str) -> list[dict]:
        v = data.get(key, [])
        if not isinstance(v, list):
            self.fail(key, f"expected an array of tables, got {type(v).__name__}; write each entry as [[{key}]]")
        for i, item in enumerate(v):
            self.table(item, f"{key}[{i}]", f"[[{key}]]")
        return v

    def xy(self, tbl: Mapping, where: str) -> tuple[float, float]:
        x, y = self.number(tbl, "x", where), self.number(tbl, "y", where)
        self.inside(x, y, where)
        return x, y

    # ------------------------------------------------------------------ the file
    def load(self, path: Path) -> Mission:
        try:
            raw = path.read_bytes()
        except OSError as exc:
            self.fail("file", f"cannot read it ({exc.strerror or exc}); check the path")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.fail("file", f"not UTF-8 text ({exc.reason} at byte {exc.start}); save the file as UTF-8")
        return self.load_text(text)

    def load_text(self, text: str) -> Mission:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            self.fail("TOML syntax", f"{exc}; fix the TOML at that line")
        return self.build(data)

    def build(self, data: dict) -> Mission:
        """The mission in the parsed file, section by section in the order problems are reported."""
        self.element_owner: dict[str, str] = {}
        self.check_sections(data)
        # operational area first: every position is checked against it
        self.op = self.operational_area_section(data["operational_area"])
        m = data["mission"]
        name, lat, lon, start_time, time_limit, wp_radius, dt = self.mission_section(m)
        launch = self.launch_section(data["launch"])
        recovery, rec_radius = self.recovery_section(data["recovery"])
        waypoints = self.waypoints_section(data)
        areas = self.mission_areas_section(data)
        area_names = [a.name for a in areas]
        transmission = self.transmission_section(data)
        nogo = self.rects_section(data, "nogo", 400.0, 500.0)
        barriers = self.rects_section(data, "barriers", 40.0, 700.0)
        obstacles = self.obstacles_section(data)
        # mission priority and requirements (need the areas and the transmission)
        priority = self.priority(m, area_names)
        requires = self.requires(m, waypoints, areas, transmission)

        vehicle = self.overrides(data.get("vehicle", {}), "vehicle", Vehicle)
        current = self.overrides(data.get("current", {}), "current", Current)

        self.elements = {
            "nogo": [z.name for z in nogo],
            "barrier": [b.name for b in barriers],
            "obstacle": [o.name for o in obstacles],
            "mission_area": area_names,
        }
        self.transmission = transmission
        space, bindings = self.parameters(self.array(data, "parameters"), area_names)

        mission = Mission(
            name=name,
            origin_lat=lat,
            origin_lon=lon,
            operational_area=self.op,
            launch=launch,
            recovery=recovery,
            recovery_radius=rec_radius,
            waypoints=tuple(waypoints),
            mission_areas=tuple(areas),
            priority=tuple(priority),
            transmission=transmission,
            nogo=nogo,
            barriers=barriers,
            obstacles=tuple(obstacles),
            vehicle=vehicle,
            current=current,
            start_time_s=start_time,
            time_limit_s=time_limit,
            waypoint_radius=wp_radius,
            space=space,
            bindings=bindings,
            score_tree={},
            mission_requires=tuple(requires),
            dt=dt,
            source=self.label,
        )
        tree = self.score_tree(data["score_tree"], mission)
        return dataclasses.replace(mission, score_tree=tree)

    # ------------------------------------------------------------------ sections
    def check_sections(self, data: dict) -> None:
        """No unknown section, every required one, and a table where a table belongs."""
        for key in data:
            if key not in _SECTIONS:
                hint = difflib.get_close_matches(key, _SECTIONS, n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                self.fail(key, f"unknown section{did}; allowed sections: {_names(_SECTIONS)}")
        for key in _REQUIRED_SECTIONS:
            if key not in data:
                header = f"[[{key}]]" if key in _ARRAY_SECTIONS else f"[{key}]"
                self.fail(key, f"missing required section; add {header} to the file")
        for key in _SECTIONS:
            if key in data and key not in _ARRAY_SECTIONS:
                self.table(data[key], key, f"[{key}]")

    def operational_area_section(self, op: Mapping) -> Rect:
        self.keys(op, "operational_area", ("x", "y", "width", "height"))
        return Rect(
            "operational_area",
            self.number(op, "x", "operational_area"),
            self.number(op, "y", "operational_area"),
            self.number(op, "width", "operational_area", positive=True),
            self.number(op, "height", "operational_area", positive=True),
        )

    def mission_section(self, m: Mapping) -> tuple[str, float, float, float, float, float, float]:
        """[mission]'s name, origin (lat, lon), start time, time limit, waypoint radius and step."""
        self.keys(
            m,
            "mission",
            ("name", "origin", "start_time_s", "time_limit_s"),
            ("waypoint_radius_m", "dt_s", "priority", "requires"),
        )
        name = self.string(m, "name", "mission")
        origin = self.table(m["origin"], "mission.origin", "origin = { lat = ..., lon = ... }")
        self.keys(origin, "mission.origin", ("lat", "lon"))
        lat = self.number(origin, "lat", "mission.origin", low=-89.9, high=89.9)
        lon = self.number(origin, "lon", "mission.origin", low=-180.0, high=180.0)
        start_time = self.number(m, "start_time_s", "mission", low=0.0, high=86400.0)
        time_limit = self.number(m, "time_limit_s", "mission", positive=True)
        wp_radius = self.number(m, "waypoint_radius_m", "mission", 25.0, positive=True)
        dt = self.number(m, "dt_s", "mission", 2.0, positive=True)
        if dt > time_limit:
            self.fail(
                "mission.dt_s", f"step {_fmt(dt)} s exceeds time_limit_s {_fmt(time_limit)} s; use a smaller step"
            )
        return name, lat, lon, start_time, time_limit, wp_radius, dt

    def launch_section(self, launch_t: Mapping) -> tuple[float, float]:
        self.keys(launch_t, "launch", ("x", "y"))
        return self.xy(launch_t, "launch")

    def recovery_section(self, rec_t: Mapping) -> tuple[tuple[float, float], float]:
        """The recovery point and its radius."""
        self.keys(rec_t, "recovery", ("x", "y"), ("radius_m",))
        recovery = self.xy(rec_t, "recovery")
        return recovery, self.number(rec_t, "radius_m", "recovery", 15.0, positive=True)

    def waypoints_section(self, data: Mapping) -> list[tuple[float, float]]:
        waypoints = []
        for i, w in enumerate(self.array(data, "waypoints")):
            where = f"waypoints[{i}]"
            self.keys(w, where, ("x", "y"))
            waypoints.append(self.xy(w, where))
        return waypoints

    def mission_areas_section(self, data: Mapping) -> list[MissionArea]:
        areas = []
        for i, a in enumerate(self.array(data, "mission_areas")):
            where = f"mission_areas[{i}]"
            self.keys(a, where, ("name", "x", "y", "dwell_s"), ("width", "height"))
            nm = self.element_name(a, where)
            x, y = self.xy(a, where)
            areas.append(
                MissionArea(
                    nm,
                    x,
                    y,
                    self.number(a, "width", where, 500.0, positive=True),
                    self.number(a, "height", where, 500.0, positive=True),
                    self.number(a, "dwell_s", where, low=0.0),
                )
            )
        return areas

    def transmission_section(self, data: Mapping) -> Transmission | None:
        """The optional [transmission] area (None when the file has none)."""
        if "transmission" not in data:
            return None
        t = data["transmission"]
        where = "transmission"
        self.keys(t, where, ("x", "y"), ("name", "width", "height", "window_start_s", "window_length_s", "duration_s"))
        nm = self.element_name(t, where, "transmission")
        x, y = self.xy(t, where)
        d = Transmission("transmission", 0.0, 0.0)
        return Transmission(
            nm,
            x,
            y,
            self.number(t, "width", where, d.width, positive=True),
            self.number(t, "height", where, d.height, positive=True),
            self.number(t, "window_start_s", where, d.window_start_s, low=0.0),
            self.number(t, "window_length_s", where, d.window_length_s, positive=True),
            self.number(t, "duration_s", where, d.duration_s, low=0.0),
        )

    def rects_section(self, data: Mapping, section: str, width: float, height: float) -> tuple[Rect, ...]:
        """[[nogo]] or [[barriers]]: named rectangles with default sizes."""
        out = []
        for i, r in enumerate(self.array(data, section)):
            where = f"{section}[{i}]"
            self.keys(r, where, ("name", "x", "y"), ("width", "height"))
            nm = self.element_name(r, where)
            x, y = self.xy(r, where)
            out.append(
                Rect(
                    nm,
                    x,
                    y,
                    self.number(r, "width", where, width, positive=True),
                    self.number(r, "height", where, height, positive=True),
                )
            )
        return tuple(out)

    def obstacles_section(self, data: Mapping) -> list[Triangle]:
        obstacles = []
        for i, o in enumerate(self.array(data, "obstacles")):
            where = f"obstacles[{i}]"
            self.keys(o, where, ("name", "x", "y"), ("side",))
            nm = self.element_name(o, where)
            x, y = self.xy(o, where)
            obstacles.append(Triangle(nm, x, y, self.number(o, "side", where, 50.0, positive=True)))
        return obstacles

    def priority(self, m: Mapping, area_names: list[str]) -> list[str]:
        """mission.priority: an ordering of the mission areas (default: file order)."""
        if "priority" not in m:
            return list(area_names)
        priority = self.string_list(m["priority"], "mission.priority")
        if sorted(priority) != sorted(area_names) or len(set(priority)) != len(priority):
            self.fail(
                "mission.priority",
                f"{priority!r} is not an ordering of the mission areas; list each of {_names(area_names)} exactly once",
            )
        return priority

    def requires(self, m: Mapping, waypoints: list, areas: list, transmission: Transmission | None) -> list[str]:
        """mission.requires: objectives the mission has (default: areas, transmission, time, where present)."""
        if "requires" not in m:
            return [
                r
                for r in ("mission_areas", "transmission", "mission_time")
                if r == "mission_time"
                or (r == "mission_areas" and areas)
                or (r == "transmission" and transmission is not None)
            ]
        requires = self.string_list(m["requires"], "mission.requires")
        for r in requires:
            if r not in _REQUIRES:
                self.fail("mission.requires", f"unknown objective {r!r}; allowed: {_names(_REQUIRES)}")
        if len(set(requires)) != len(requires):
            self.fail("mission.requires", f"{requires!r} lists an objective twice; list each once")
        present = {
            "waypoints": bool(waypoints),
            "mission_areas": bool(areas),
            "transmission": transmission is not None,
            "mission_time": True,
        }
        header = {"waypoints": "[[waypoints]]", "mission_areas": "[[mission_areas]]", "transmission": "[transmission]"}
        for r in requires:
            if not present[r]:
                self.fail(
                    "mission.requires",
                    f"requires {r!r} but the mission has no {r.replace('_', ' ')}; "
                    f"add {header[r]} or drop {r!r} from requires",
                )
        return requires

    # ------------------------------------------------------------------ vehicle and current
    def overrides(self, tbl: Mapping, where: str, cls: type) -> Any:
        defaults = cls()
        fields = {f.name: getattr(defaults, f.name) for f in dataclasses.fields(cls)}
        self.keys(tbl, where, (), tuple(fields))
        values: dict[str, object] = {}
        for key, v in tbl.items():
            field = f"{where}.{key}"
            default = fields[key]
            if isinstance(default, bool):
                if not isinstance(v, bool):
                    self.fail(field, f"expected true or false, got {v!r}")
                values[key] = v
            elif isinstance(default, (int, float)):
                num = self.check_number(v, field)
                values[key] = int(num) if isinstance(default, int) and float(num).is_integer() else num
            elif isinstance(default, str):
                if not isinstance(v, str):
                    self.fail(field, f'expected a string, got {v!r}; write {key} = "..."')
                values[key] = v
            else:
                values[key] = v
        obj = dataclasses.replace(defaults, **values)
        if cls is Vehicle:
            positive = (
                "cruise_speed",
                "max_speed",
                "battery_wh",
                "speed_gain",
                "surge_time_constant_s",
                "yaw_time_constant_s",
                "max_turn_rate_dps",
            )
            for key in positive:
                if getattr(obj, key) <= 0:
                    self.fail(f"vehicle.{key}", f"{_fmt(getattr(obj, key))} must be > 0; give a positive number")
            for key in ("start_battery", "critical_battery"):
                if not 0.0 <= getattr(obj, key) <= 1.0:
                    self.fail(
                        f"vehicle.{key}",
                        f"{_fmt(getattr(obj, key))} is a fraction of the battery; use a value in [0, 1]",
                    )
            if obj.max_speed < obj.cruise_speed:
                self.fail(
                    "vehicle.max_speed",
                    f"{_fmt(obj.max_speed)} is below cruise_speed {_fmt(obj.cruise_speed)}; "
                    "raise max_speed or lower cruise_speed",
                )
        if cls is Current:
            if obj.speed < 0 or obj.perturbation < 0:
                self.fail(
                    "current.speed" if obj.speed < 0 else "current.perturbation",
                    "must be >= 0; give a non-negative speed",
                )
            if obj.period_h <= 0:
                self.fail("current.period_h", f"{_fmt(obj.period_h)} must be > 0; give the tidal period in hours")
        return obj

    # ------------------------------------------------------------------ parameters
    def parameters(self, specs: list[dict], area_names: list[str]) -> tuple[StateSpace, tuple[Binding, ...]]:
        if not specs:
            self.fail("parameters", "no [[parameters]] entries; a study needs at least one parameter")
        params: list[Parameter] = []
        bindings: list[Binding] = []
        seen_names: dict[str, str] = {}
        seen_targets: dict[tuple, str] = {}
        for i, p in enumerate(specs):
            where = f"parameters[{i}]"
            kind = self.string(p, "kind", where)
            if kind not in _PARAM_KINDS:
                self.fail(f"{where}.kind", f"unknown kind {kind!r}; allowed: {_names(_PARAM_KINDS)}")
            if p.get("target") == "mission_areas.priority" and kind != "permutation":
                self.fail(
                    f"{where}.kind",
                    f'kind {kind!r} cannot set mission_areas.priority; use kind = "permutation" '
                    "with items = the mission-area names",
                )
            required, optional = _PARAM_KEYS[kind]
            self.keys(p, where, required, optional)
            pname = self.string(p, "name", where)
            if pname in seen_names:
                self.fail(
                    f"{where}.name",
                    f"duplicate parameter name {pname!r} (also {seen_names[pname]}); give every parameter its own name",
                )
            seen_names[pname] = where
            binding = self.target(p, where, pname)
            key = (binding.kind, binding.name, binding.field)
            if key in seen_targets:
                self.fail(
                    f"{where}.target",
                    f"{p['target']!r} is already set by {seen_targets[key]}; give each field one parameter",
                )
            seen_targets[key] = where
            if binding.field == "priority":
                params.append(self.priority_parameter(p, where, pname, area_names))
            elif kind == "permutation":
                self.fail(
                    f"{where}.kind",
                    f"a permutation can only target mission_areas.priority, not {p['target']!r}; "
                    "use continuous, integer or categorical",
                )
            elif kind == "categorical":
                params.append(self.categorical_parameter(p, where, pname, binding))
            else:
                params.append(self.numeric_parameter(p, where, kind, pname, binding))
            bindings.append(binding)
        try:
            space = StateSpace(params)
        except ValueError as exc:  # pragma: no cover - everything is checked above
            self.fail("parameters", str(exc))
        return space, tuple(bindings)

    def priority_parameter(self, p: Mapping, where: str, pname: str, area_names: list[str]) -> Permutation:
        """A permutation of the mission areas' priority order: every area named exactly once."""
        tfield = f"{where}.target"
        items = self.string_list(p["items"], f"{where}.items")
        if sorted(items) != sorted(area_names) or len(set(items)) != len(items):
            self.fail(
                f"{where}.items",
                f"{items!r} is not the mission-area names; list each of {_names(area_names)} exactly once",
            )
        if len(items) < 2:
            self.fail(
                f"{tfield}",
                "a priority permutation needs at least 2 mission areas; drop this parameter or add [[mission_areas]]",
            )
        return Permutation(pname, tuple(items))

    def categorical_parameter(self, p: Mapping, where: str, pname: str, binding: Binding) -> Categorical:
        """A choice among at least two distinct numbers, each within the target field's range."""
        choices = p["choices"]
        if not isinstance(choices, list):
            self.fail(
                f"{where}.choices",
                f"expected a list of numbers, got {choices!r}; write e.g. choices = [0.1, 0.2]",
            )
        values = [self.check_number(c, f"{where}.choices[{j}]") for j, c in enumerate(choices)]
        if len(values) < 2 or len(set(values)) != len(values):
            self.fail(f"{where}.choices", f"{choices!r} needs at least 2 distinct values; add or de-duplicate choices")
        self.value_range(binding, min(values), max(values), f"{where}.choices")
        return Categorical(pname, tuple(values))

    def numeric_parameter(
        self, p: Mapping, where: str, kind: str, pname: str, binding: Binding
    ) -> Integer | Continuous:
        """An integer or continuous range (optionally log-scaled) within the target field's range."""
        if kind == "integer":
            for k in ("low", "high"):
                if isinstance(p[k], bool) or not isinstance(p[k], int):
                    self.fail(
                        f"{where}.{k}",
                        f"an integer parameter needs whole-number bounds, got {p[k]!r}; "
                        'write e.g. 3, or use kind = "continuous"',
                    )
        low = self.check_number(p["low"], f"{where}.low")
        high = self.check_number(p["high"], f"{where}.high")
        if low >= high:
            self.fail(f"{where}.low", f"low={_fmt(low)} must be < high={_fmt(high)}; swap or widen the bounds")
        log = False
        if "log" in p:
            log = p["log"]
            if not isinstance(log, bool):
                self.fail(f"{where}.log", f"expected true or false, got {log!r}")
            if log and low <= 0:
                self.fail(f"{where}.low", f"log scale needs low > 0, got {_fmt(low)}; raise low or set log = false")
        self.value_range(binding, low, high, where)
        return Integer(pname, int(low), int(high)) if kind == "integer" else Continuous(pname, low, high, log)

    def target(self, p: Mapping, where: str, pname: str) -> Binding:
        field = f"{where}.target"
        target = self.string(p, "target", where)
        parts = target.split(".")
        kinds = tuple(TARGET_FIELDS)
        kind = parts[0]
        if kind not in TARGET_FIELDS or not 2 <= len(parts) <= 3 or not all(parts):
            self.fail(
                field,
                f"{target!r} is not a target; write '<kind>.<field>' or '<kind>.<element name>.<field>' "
                f"with kind one of {_names(kinds)}",
            )
        if kind in _UNNAMED_TARGETS:
            if len(parts) == 3:
                self.fail(field, f"{kind!r} takes no element name; write '{kind}.{parts[2]}'")
            name, attr = None, parts[1]
            if kind == "transmission" and self.transmission is None:
                self.fail(
                    field,
                    f"{target!r} targets the transmission area but the file has no [transmission]; "
                    "add [transmission] or drop this parameter",
                )
            if kind == "mission_areas" and not self.elements["mission_area"]:
                self.fail(field, f"{target!r} but the file has no [[mission_areas]]; add them or drop this parameter")
        else:
            section, words = _NAMED_TARGETS[kind]
            known = self.elements[kind]
            if len(parts) == 2:
                example = known[0] if known else "<name>"
                self.fail(
                    field,
                    f"{kind!r} needs an element name; write '{kind}.{example}.{parts[1]}' "
                    f"(known {words}: {_names(known)})",
                )
            name, attr = parts[1], parts[2]
            if name not in known:
                self.fail(
                    field,
                    f"unknown element '{kind}.{name}' (known {words}: {_names(known)}); "
                    f"name an element defined in [[{section}]]",
                )
        if attr not in TARGET_FIELDS[kind]:
            self.fail(field, f"{kind!r} has no settable field {attr!r}; settable: {_names(TARGET_FIELDS[kind])}")
        return Binding(pname, kind, name, attr)

    def value_range(self, b: Binding, low: float, high: float, where: str) -> None:
        """Check a parameter's range against what its field can hold (``where`` is the entry or its choices)."""
        field = b.field
        bound = where if where.endswith(".choices") else None
        if field in ("x", "y"):
            op = self.op
            c, size = (op.x, op.width) if field == "x" else (op.y, op.height)
            lo, hi = c - size / 2, c + size / 2
            if low < lo or high > hi:
                self.fail(
                    bound or f"{where}.{'low' if low < lo else 'high'}",
                    f"{field} range {_fmt(low)}..{_fmt(high)} leaves the operational area "
                    f"({field} {_fmt(lo)}..{_fmt(hi)}); keep positions inside it",
                )
            return
        limits = {
            "start_time_s": (0.0, 86400.0, "seconds after local midnight"),
            "start_battery": (0.0, 1.0, "a fraction of the battery"),
            "window_start_s": (0.0, math.inf, "seconds after the mission start"),
            "window_length_s": (0.0, math.inf, "a duration in seconds"),
            "dwell_s": (0.0, math.inf, "a duration in seconds"),
        }
        if field in limits:
            lo, hi, what = limits[field]
            if low < lo or high > hi:
                self.fail(
                    bound or f"{where}.{'low' if low < lo else 'high'}",
                    f"{b.kind}.{field} is {what}; keep the range {_fmt(low)}..{_fmt(high)} "
                    f"within {_fmt(lo)}..{_fmt(hi)}",
                )

    # ------------------------------------------------------------------ score tree
    def score_tree(self, spec: Any, mission: Mission) -> dict:
        self.metric_list = metric_names(mission)
        self.metric_index = {n: i for i, n in enumerate(self.metric_list)}
        self.mission = mission
        self.check_node(spec, "score_tree", root=True)
        self.used: dict[int, str] = {}
        (tree,) = self.resolve(spec, "score_tree", None)
        for i, metric in enumerate(self.metric_list):
            if i not in self.used:
                self.fail(
                    "score_tree",
                    f"metric {metric!r} (column {i}) is not in the tree; add it to the scores of "
                    "one node (every score column must appear exactly once)",
                )
        try:
            ScoreTree.from_mapping(tree).validate(len(self.metric_list))
        except ValueError as exc:  # pragma: no cover - checked above
            self.fail("score_tree", str(exc))
        return tree

    def check_node(self, spec: Any, where: str, root: bool = False) -> None:
        """Syntax of a node and its descendants (before replication, so empty for_each nodes are checked too)."""
        bare = re.sub(r"\[\d+\]", "", where)
        self.table(spec, where, f"[{bare}]" if root else f"[[{bare}]]")
        self.keys(spec, where, ("scores",), ("name", "children", "for_each"))
        if "name" in spec and not isinstance(spec["name"], str):
            self.fail(f"{where}.name", f'expected a string, got {spec["name"]!r}; write name = "..."')
        scores = spec["scores"]
        if not isinstance(scores, list) or not scores or not all(isinstance(s, str) for s in scores):
            self.fail(
                f"{where}.scores",
                f'expected a non-empty list of metric names, got {scores!r}; write e.g. scores = ["mission_success"]',
            )
        if "for_each" in spec:
            fe = spec["for_each"]
            if root:
                self.fail(f"{where}.for_each", "the root node cannot be replicated; move for_each to a child node")
            if fe not in ELEMENT_KINDS:
                self.fail(f"{where}.for_each", f"unknown element kind {fe!r}; allowed: {_names(ELEMENT_KINDS)}")
        children = spec.get("children", [])
        if not isinstance(children, list):
            self.fail(
                f"{where}.children",
                f"expected an array of tables, got {type(children).__name__}; write each child as [[{bare}.children]]",
            )
        for j, child in enumerate(children):
            self.check_node(child, f"{where}.children[{j}]")

    def resolve(self, spec: Mapping, where: str, current: tuple[str, str] | None) -> list[dict]:
        if "for_each" in spec:
            kind = spec["for_each"]
            return [self.resolve_body(spec, where, (kind, e)) for e in element_names(self.mission, kind)]
        return [self.resolve_body(spec, where, current)]

    def resolve_body(self, spec: Mapping, where: str, current: tuple[str, str] | None) -> dict:
        elem = f" ({current[0]} {current[1]!r})" if current else ""

        def sub(text: str, field: str) -> str:
            if "{name}" in text:
                if current is None:
                    self.fail(
                        field,
                        f'{text!r} uses {{name}} outside a for_each node; add for_each = "..." to this '
                        "node or an ancestor, or write the element name",
                    )
                text = text.replace("{name}", current[1])
            return text

        indices = []
        for j, pattern in enumerate(spec["scores"]):
            field = f"{where}.scores[{j}]"
            metric = sub(pattern, field)
            if metric not in self.metric_index:
                hint = difflib.get_close_matches(metric, self.metric_list, n=1)
                known = f"did you mean {hint[0]!r}?" if hint else f"known metrics: {_names(self.metric_list)}"
                self.fail(
                    field,
                    f"unknown metric {metric!r}{elem} ({known}); use a name from "
                    "sim.uuv.metrics.metric_names for this mission",
                )
            i = self.metric_index[metric]
            if i in self.used:
                self.fail(
                    field,
                    f"metric {metric!r}{elem} appears twice (also at {self.used[i]}); "
                    "list each metric in exactly one node",
                )
            self.used[i] = field + elem
            indices.append(i)
        name = sub(spec["name"], f"{where}.name") if "name" in spec else self.metric_list[indices[0]]
        children = []
        for j, child in enumerate(spec.get("children", [])):
            children.extend(self.resolve(child, f"{where}.children[{j}]", current))
        return {"name": name, "indices": indices, "children": children}
