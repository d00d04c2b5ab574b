"""A UUV mission: the fixed elements of a range day and the parameters a study varies.

Everything is in a local metric frame (x east, y north, metres) around the range origin
given in latitude/longitude (:mod:`sim.uuv.geo` converts).  Times are seconds; the mission
clock starts at the scenario's start time (seconds after local midnight, which sets the
tide).  A :class:`Mission` is immutable; a batch of scenarios is the mission with its
parameters set from unit-cube rows (:mod:`sim.uuv.scenario`).

Element kinds follow Tables 3.2 and 4.1 of the dissertation: operational area,
waypoints, mission areas (survey and loiter, in a priority order), a transmission area
(surface inside it during a time window), no-go areas, barrier no-go areas, minor
triangular obstacles and a recovery point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from rapt.space import StateSpace
from sim.uuv.bias import Bias
from sim.uuv.missionnoise import ExecutionNoise

__all__ = [
    "Rect",
    "Triangle",
    "MissionArea",
    "Transmission",
    "Vehicle",
    "Current",
    "Binding",
    "Mission",
    "TARGET_FIELDS",
    "FIELD_RESOLUTION",
]


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle given by its centre and size (no-go areas, barriers, areas)."""

    name: str
    x: float
    y: float
    width: float
    height: float


@dataclass(frozen=True)
class Triangle:
    """An equilateral triangular obstacle (pointing north) of side ``side`` around a centre."""

    name: str
    x: float
    y: float
    side: float = 50.0


@dataclass(frozen=True)
class MissionArea:
    """A survey area: reach it and loiter for ``dwell_s`` seconds (counts only while inside)."""

    name: str
    x: float
    y: float
    width: float = 500.0
    height: float = 500.0
    dwell_s: float = 300.0


@dataclass(frozen=True)
class Transmission:
    """Surface inside the area while the window is open and stay ``duration_s`` to send data.

    The window opens ``window_start_s`` after the mission start and lasts ``window_length_s``.
    """

    name: str
    x: float
    y: float
    width: float = 700.0
    height: float = 750.0
    window_start_s: float = 1800.0
    window_length_s: float = 3600.0
    duration_s: float = 120.0


@dataclass(frozen=True)
class Vehicle:
    """A torpedo UUV: speeds, a 3-DOF manoeuvring model, battery and sensors.

    The speed loop drives the through-water surge towards ``speed_gain`` times the
    commanded speed, at most ``max_speed`` (1: the vehicle reaches what it is asked; a
    vehicle without a speed loop, e.g. a thruster-throttle ROV, reaches a fixed share).
    A measured ``speed_curve`` of (commanded, reached) m/s knots replaces that rule where a
    vehicle's answer is no single gain (a velocity controller that falls short at low
    speeds and saturates below its nominal top speed): reached speed is interpolated
    between the knots, from (0, 0), and held at the last knot's beyond it; ``max_speed``
    then only caps what the autonomy commands.
    Propulsion power is ``drag_w * (speed / cruise_speed)^power_exponent`` plus ``hotel_w``:
    3 is a torpedo's (drag grows with the square of speed, power with its cube); a
    thruster vehicle's draw rises about linearly with speed (exponent near 1), since its
    thrusters' current follows their command while thrust goes with its square.  The
    battery starts at ``start_battery`` of ``battery_wh``.  ``ascent_rate_mps`` is how fast
    the vehicle rises from its running depth (:data:`sim.uuv.interface.DEPTH_M`) when told
    to surface, and dives back (0: instantaneously, surfaced in the step it is told).  At the
    surface a thruster vehicle is another machine: its vertical thrusters push it against
    the surface and its horizontal ones lose water, so it moves at most
    ``surface_max_speed`` (0: no limit) and draws ``surface_power_w`` more (ArduSub's
    BlueROV2 model: 0.33 m/s whatever is asked, 350 W).
    ``velocity_control`` says what the speed loop drives: ``"surge"``, the speed along the
    bow (a torpedo: it goes where it points, and a turn keeps its speed); ``"vector"``, the
    commanded velocity in the earth frame, with the heading held apart (a thruster vehicle in
    ArduSub's GUIDED mode: a new course is reached by slowing the old one down and building
    the new one up, so a reversal passes near standstill, and the bow is irrelevant to the
    track).  A vector loop with an integrator answers in two parts: ``1 - slow_share`` of a
    change within ``surge_time_constant_s``, the rest within ``slow_time_constant_s`` (ArduSub:
    about two thirds in a few seconds, the rest over tens of seconds).  The autonomy returns home when
    its estimate of the energy to get there, times ``reserve_factor``, reaches the charge
    left; below ``critical_battery`` it also ignores no-go areas.
    """

    cruise_speed: float = 2.0
    max_speed: float = 3.0
    surge_time_constant_s: float = 4.0
    max_turn_rate_dps: float = 12.0
    yaw_time_constant_s: float = 3.0
    sway_damping: float = 0.5
    battery_wh: float = 1000.0
    start_battery: float = 1.0
    hotel_w: float = 40.0
    drag_w: float = 160.0
    reserve_factor: float = 1.3
    critical_battery: float = 0.05
    sonar_range_m: float = 100.0
    sonar_fov_deg: float = 120.0
    ins_drift_m_per_s: float = 0.05
    gps_sigma_m: float = 3.0
    speed_gain: float = 1.0
    power_exponent: float = 3.0
    ascent_rate_mps: float = 0.0
    heading_time_s: float = 4.0
    speed_curve: tuple[tuple[float, float], ...] = ()
    surface_max_speed: float = 0.0
    surface_power_w: float = 0.0
    velocity_control: str = "surge"
    slow_share: float = 0.0
    slow_time_constant_s: float = 30.0


#: What a vehicle's speed loop drives (``Vehicle.velocity_control``).
VELOCITY_CONTROLS = ("surge", "vector")


@dataclass(frozen=True)
class Current:
    """Tidal current by time of day: a sinusoid of period ``period_h``, flowing at ``speed``
    towards ``direction_deg`` (compass) at ``peak_hour`` and the opposite way half a period
    later (the dissertation: 3 m/s NE at 2 am to 3 m/s SW at 12 pm), with seeded random
    perturbations of ``perturbation`` m/s in stochastic runs."""

    speed: float = 1.0
    direction_deg: float = 45.0
    peak_hour: float = 2.0
    period_h: float = 20.0
    perturbation: float = 0.1


#: Parameter targets: element kind -> settable fields.
TARGET_FIELDS: dict[str, tuple[str, ...]] = {
    "mission": ("start_time_s",),
    "vehicle": ("start_battery",),
    "transmission": ("x", "y", "window_start_s", "window_length_s"),
    "nogo": ("x", "y"),
    "barrier": ("x", "y"),
    "obstacle": ("x", "y"),
    "mission_area": ("x", "y", "dwell_s"),
    "mission_areas": ("priority",),
}

#: The finest step a range sets each target field to, the default ``resolution`` of a continuous
#: parameter on it: a position surveyed and flown to 0.1 m, a time to 1 s, a charge to 0.1 %.
#: Scenarios leave a study at these steps, so what the plan says is what the range can set up.
FIELD_RESOLUTION: dict[str, float] = {
    "x": 0.1,
    "y": 0.1,
    "start_time_s": 1.0,
    "window_start_s": 1.0,
    "window_length_s": 1.0,
    "dwell_s": 1.0,
    "start_battery": 0.001,
}


@dataclass(frozen=True)
class Binding:
    """Where a state-space parameter goes: ``kind`` / element ``name`` / ``field``.

    ``mission.start_time_s``, ``vehicle.start_battery`` and ``mission_areas.priority`` have
    no element name; the priority is a permutation of the mission-area names.
    """

    parameter: str
    kind: str
    name: str | None
    field: str


@dataclass(frozen=True)
class Mission:
    """A mission file, loaded and validated (see :func:`sim.uuv.load_mission`).

    ``mission_requires`` names the level-2 mission objectives that mission success needs
    (Table 3.2: waypoints are recommended, not required; the chapter 6 mission requires
    only its waypoint).  Safety success needs every safety rule.  ``score_tree`` is a
    rapt score-tree mapping (``name``, ``indices`` into :func:`sim.uuv.metrics.metric_names`,
    ``children``).  ``execution_bias`` is the day's bias (neutral without an
    ``[execution_bias]`` table: then everything runs exactly as without the field).
    """

    name: str
    origin_lat: float
    origin_lon: float
    operational_area: Rect
    launch: tuple[float, float]
    recovery: tuple[float, float]
    recovery_radius: float
    waypoints: tuple[tuple[float, float], ...]
    mission_areas: tuple[MissionArea, ...]
    priority: tuple[str, ...]
    transmission: Transmission | None
    nogo: tuple[Rect, ...]
    barriers: tuple[Rect, ...]
    obstacles: tuple[Triangle, ...]
    vehicle: Vehicle
    current: Current
    start_time_s: float
    time_limit_s: float
    waypoint_radius: float
    space: StateSpace
    bindings: tuple[Binding, ...]
    score_tree: Mapping[str, Any]
    mission_requires: tuple[str, ...] = ("mission_areas", "transmission", "mission_time")
    dt: float = 2.0
    source: str = field(default="<memory>", compare=False)
    #: The day's execution bias (``[execution_bias]``, :mod:`sim.uuv.missionbias`): the water and
    #: vehicle the world flies, while the autonomy plans with the file's tide table and vehicle;
    #: every simulation composes its own bias argument on top (:func:`sim.uuv.bias.compose`).
    execution_bias: Bias = field(default_factory=Bias)
    #: Where that bias came from: the table's ``source`` ("" when it names none), None when
    #: the file has no ``[execution_bias]`` table.
    execution_bias_source: str | None = None
    #: The day's execution noise (``[execution_noise]``, :mod:`sim.uuv.missionnoise`): the sigmas a plan of this
    #: mission dithers by; no simulation reads it. None without the table.
    execution_noise: ExecutionNoise | None = None

    @property
    def dim(self) -> int:
        """Width of the unit cube a study samples (a permutation takes one key per item)."""
        return self.space.dim

    def parameter_of(self, coordinate: int) -> str:
        """The name of the parameter that unit-cube ``coordinate`` encodes."""
        return next(
            p.name
            for p in self.space.parameters
            if self.space.slice_of(p.name).start <= coordinate < self.space.slice_of(p.name).stop
        )
