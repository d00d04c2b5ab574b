"""Mission files: a TOML description of a range day, loaded into a :class:`sim.uuv.mission.Mission`.

:func:`load_mission` reads and checks the whole file; every problem is a
:class:`~sim.uuv.missionfields.MissionFileError` of ONE line naming the file, the field and the fix, e.g.::

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
                                  #   speed_curve=[[1.0, 0.87], [2.0, 1.93]]: measured (commanded,
                                  #   reached) m/s knots, replacing speed_gain where given
                                  #   surface_max_speed=0.33, surface_power_w=180: at the surface
                                  #   velocity_control="vector", slow_share=0.3, slow_time_constant_s=25:
                                  #   an earth-frame velocity loop (default "surge": along the bow)
                                  #   (0: no limit, no extra draw); rapt-plan calibrate measures them
    [current]                     # optional overrides of sim.uuv.mission.Current fields
    [execution_bias]              # optional: the day's water and vehicle as logs showed them
                                  #   (sim.uuv.missionbias; rapt-plan calibrate --bias writes it)
    [execution_noise]             # optional: the day's execution noise, the sigmas a plan dithers by
                                  #   (sim.uuv.missionnoise; rapt-plan calibrate --bias writes it)

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
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim.uuv.mission import VELOCITY_CONTROLS, Current, Mission, MissionArea, Rect, Transmission, Triangle, Vehicle
from sim.uuv.missionbias import read_execution_bias
from sim.uuv.missionfields import MISSING, FieldChecker, fmt, names
from sim.uuv.missionnoise import read_execution_noise
from sim.uuv.missionparameters import ParameterReader
from sim.uuv.missionscoretree import ScoreTreeReader

__all__ = ["load_mission", "load_mission_text"]

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
    "execution_bias",
    "execution_noise",
    "parameters",
    "score_tree",
)
_REQUIRED_SECTIONS = ("mission", "operational_area", "launch", "recovery", "parameters", "score_tree")
_ARRAY_SECTIONS = ("waypoints", "mission_areas", "nogo", "barriers", "obstacles", "parameters")
_REQUIRES = ("waypoints", "mission_areas", "transmission", "mission_time")


def load_mission(path: str | Path) -> Mission:
    """Read, check and build the mission in the TOML file ``path``."""
    return _Loader(str(path)).load(Path(path))


def load_mission_text(text: str, label: str) -> Mission:
    """Check and build the mission in TOML ``text`` (e.g. the copy a field plan embeds).

    ``label`` names where the text came from, in errors and as the mission's ``source``.
    """
    return _Loader(label).load_text(text)


class _Loader(FieldChecker):
    """Reads a whole mission file: its sections here, parameters and score tree by their readers."""

    def element_name(self, tbl: Mapping, where: str, default: Any = MISSING) -> str:
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

    def inside(self, x: float, y: float, field: str, what: str = "centre") -> None:
        op = self.op
        x0, x1, y0, y1 = op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            self.fail(
                field,
                f"{what} (x={fmt(x)}, y={fmt(y)}) lies outside the operational area "
                f"(x {fmt(x0)}..{fmt(x1)}, y {fmt(y0)}..{fmt(y1)}); move it inside",
            )

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
        day_bias, day_source = read_execution_bias(self, data)
        day_noise = read_execution_noise(self, data)

        self.elements = {
            "nogo": [z.name for z in nogo],
            "barrier": [b.name for b in barriers],
            "obstacle": [o.name for o in obstacles],
            "mission_area": area_names,
        }
        space, bindings = ParameterReader(self.label, self.op, self.elements, transmission).read(
            self.array(data, "parameters"), area_names
        )

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
            execution_bias=day_bias,
            execution_bias_source=day_source,
            execution_noise=day_noise,
        )
        tree = ScoreTreeReader(self.label, mission).read(data["score_tree"])
        return dataclasses.replace(mission, score_tree=tree)

    # ------------------------------------------------------------------ sections
    def check_sections(self, data: dict) -> None:
        """No unknown section, every required one, and a table where a table belongs."""
        for key in data:
            if key not in _SECTIONS:
                hint = difflib.get_close_matches(key, _SECTIONS, n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                self.fail(key, f"unknown section{did}; allowed sections: {names(_SECTIONS)}")
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
            self.fail("mission.dt_s", f"step {fmt(dt)} s exceeds time_limit_s {fmt(time_limit)} s; use a smaller step")
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
                f"{priority!r} is not an ordering of the mission areas; list each of {names(area_names)} exactly once",
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
                self.fail("mission.requires", f"unknown objective {r!r}; allowed: {names(_REQUIRES)}")
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
    def speed_curve(self, raw: Any) -> tuple[tuple[float, float], ...]:
        """``vehicle.speed_curve``: (commanded, reached) m/s pairs, commands > 0 and increasing, speeds >= 0 and
        non-decreasing."""
        where, fix = "vehicle.speed_curve", "write [[commanded, reached], ...] in m/s, commands increasing"
        if raw == ():
            return ()
        if not isinstance(raw, list) or not raw:
            self.fail(where, f"expected a list of [commanded, reached] pairs, got {raw!r}; {fix}")
        knots: list[tuple[float, float]] = []
        for i, pair in enumerate(raw):
            if not isinstance(pair, list) or len(pair) != 2:
                self.fail(f"{where}[{i}]", f"expected a [commanded, reached] pair, got {pair!r}; {fix}")
            cmd, got = (float(self.check_number(v, f"{where}[{i}]")) for v in pair)
            if cmd <= (knots[-1][0] if knots else 0.0) or got < 0:
                self.fail(f"{where}[{i}]", f"{pair!r}: commands must be > 0 and increasing, speeds >= 0; {fix}")
            if knots and got < knots[-1][1]:
                self.fail(
                    f"{where}[{i}]",
                    f"{pair!r}: the reached speed falls below {fmt(knots[-1][1])} m/s at a higher command; a vehicle "
                    "is never slower for being asked more: give a non-decreasing curve (a saturated one stays level)",
                )
            knots.append((cmd, got))
        return tuple(knots)

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
            obj = self.check_vehicle(obj)
        if cls is Current:
            if obj.speed < 0 or obj.perturbation < 0:
                self.fail(
                    "current.speed" if obj.speed < 0 else "current.perturbation",
                    "must be >= 0; give a non-negative speed",
                )
            if obj.period_h <= 0:
                self.fail("current.period_h", f"{fmt(obj.period_h)} must be > 0; give the tidal period in hours")
        return obj

    def check_vehicle(self, obj: Vehicle) -> Vehicle:
        """``[vehicle]``'s values checked (one line naming the field and the fix); its speed curve parsed."""
        positive = (
            "cruise_speed",
            "max_speed",
            "battery_wh",
            "speed_gain",
            "surge_time_constant_s",
            "yaw_time_constant_s",
            "max_turn_rate_dps",
            "slow_time_constant_s",
        )
        for key in positive:
            if getattr(obj, key) <= 0:
                self.fail(f"vehicle.{key}", f"{fmt(getattr(obj, key))} must be > 0; give a positive number")
        for key in ("hotel_w", "drag_w"):  # a negative draw would charge the battery by running
            if not getattr(obj, key) >= 0:
                self.fail(f"vehicle.{key}", f"{fmt(getattr(obj, key))} W is a negative power; give the W drawn, >= 0")
        for key in ("start_battery", "critical_battery"):
            if not 0.0 <= getattr(obj, key) <= 1.0:
                self.fail(
                    f"vehicle.{key}",
                    f"{fmt(getattr(obj, key))} is a fraction of the battery; use a value in [0, 1]",
                )
        if not 0.5 <= obj.power_exponent <= 4.0:
            self.fail(
                "vehicle.power_exponent",
                f"{fmt(obj.power_exponent)} is outside [0.5, 4]; use 3 for a torpedo, about 1 for a thruster vehicle",
            )
        if not obj.heading_time_s > 0:
            self.fail(
                "vehicle.heading_time_s",
                f"{fmt(obj.heading_time_s)} must be > 0; give the seconds the autopilot takes to close a heading error",
            )
        obj = dataclasses.replace(obj, speed_curve=self.speed_curve(obj.speed_curve))
        if obj.velocity_control not in VELOCITY_CONTROLS:
            self.fail(
                "vehicle.velocity_control",
                f'{obj.velocity_control!r} is not a speed loop; write "surge" (speed along the bow, a torpedo) '
                'or "vector" (an earth-frame velocity, a thruster vehicle in GUIDED)',
            )
        if not 0.0 <= obj.slow_share < 1.0:
            self.fail(
                "vehicle.slow_share",
                f"{fmt(obj.slow_share)} is the share of a speed change that comes slowly; use a value in [0, 1)",
            )
        if not obj.surface_max_speed >= 0:
            self.fail(
                "vehicle.surface_max_speed",
                f"{fmt(obj.surface_max_speed)} must be >= 0; give the m/s the vehicle reaches at the surface (0: no limit)",
            )
        if not obj.surface_power_w >= -obj.hotel_w:
            self.fail(
                "vehicle.surface_power_w",
                f"{fmt(obj.surface_power_w)} would draw less than nothing at the surface; give the extra W "
                f"drawn there, at least -hotel_w ({fmt(-obj.hotel_w)})",
            )
        if obj.ascent_rate_mps < 0:
            self.fail(
                "vehicle.ascent_rate_mps",
                f"{fmt(obj.ascent_rate_mps)} must be >= 0; give the rise rate in m/s (0: surfaces at once)",
            )
        return obj
