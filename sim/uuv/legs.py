"""A scripted back-seat: legs flown one after another by time, for a calibration run.

A calibration run ("shakedown") identifies the vehicle rather than testing the autonomy:
straight legs at fixed commanded speeds through the water, turns at the turn-rate limit, a
hold, an ascent and a dive, then the way home.  :class:`LegAutonomy` flies such a list of
:class:`Leg` in place of :class:`sim.uuv.autonomy.Autonomy` (same ``step(obs, dt, active)``,
same :class:`~sim.uuv.autonomy.Command`), in the batch simulator, in the loop and on a vehicle.

Every leg but the last is scheduled by mission time alone and commands a known function of
time (a straight leg a fixed heading and speed through water; a turn a heading that ramps
at :data:`TURN_RAMP` times the file's turn-rate limit, and at least :data:`TURN_STEP_DEG` a step,
so the autopilot saturates), so a
log's commands are known from the legs without reading the back-seat's mind.  The last leg
(``return``) steers over ground to the recovery point, crabbing against the predicted tide,
slows as it gets there and surfaces within :data:`SURFACE_WITHIN` of the recovery radius.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from rapt.errors import InputError
from sim.uuv.angles import wrap_angle
from sim.uuv.autonomy import GOAL_RETURN, GOAL_WAYPOINT, RETURN_COMPLETE, Command, Observation
from sim.uuv.environment import tidal_current
from sim.uuv.scenario import Scenarios

__all__ = [
    "Leg",
    "LegAutonomy",
    "LEG_KINDS",
    "legs_from_json",
    "legs_to_json",
    "leg_schedule",
    "leg_records",
    "leg_driver",
    "TURN_RAMP",
]

#: What a leg does: hold a heading and speed, turn, hold station (speed 0), rise, dive, go home.
LEG_KINDS = ("straight", "turn", "hold", "ascent", "dive", "return")
#: A turn's commanded heading ramps at this multiple of the file's turn-rate limit (the autopilot
#: saturates), and at least :data:`TURN_STEP_DEG` per decision step: a vehicle five times quicker
#: than its file still turns at its own limit, and shows it.
TURN_RAMP = 3.0
#: Most a turn's commanded heading moves in one decision step: under 180 degrees, so the
#: autopilot cannot take the short way round the other side.
TURN_STEP_DEG = 150.0
#: The return leg surfaces within this share of the recovery radius.
SURFACE_WITHIN = 0.5
#: The return leg's ground speed towards the recovery point: distance / this (s), at most cruise.
ARRIVE_S = 15.0


@dataclass(frozen=True)
class Leg:
    """One leg: its ``kind`` (:data:`LEG_KINDS`), a ``name``, how long it lasts (the return leg: at most),
    the commanded through-water ``speed`` (m/s), the compass ``heading_deg`` through water it holds
    (a turn: the heading it ends on), the signed ``turn_deg`` (+ clockwise) a turn makes, and
    whether the vehicle is told to ``surface``."""

    kind: str
    name: str
    duration_s: float
    speed: float
    heading_deg: float = 0.0
    turn_deg: float = 0.0
    surface: bool = False

    def __post_init__(self) -> None:
        if self.kind not in LEG_KINDS:
            raise InputError(f"leg {self.name!r}: kind {self.kind!r} is not one of {', '.join(LEG_KINDS)}")
        if not (np.isfinite(self.duration_s) and self.duration_s > 0):
            raise InputError(f"leg {self.name!r}: duration_s must be > 0, got {self.duration_s}")
        if not (np.isfinite(self.speed) and self.speed >= 0):
            raise InputError(f"leg {self.name!r}: speed must be >= 0 m/s, got {self.speed}")
        if self.kind == "turn" and not 0 < abs(self.turn_deg) <= 180:
            raise InputError(f"leg {self.name!r}: a turn's turn_deg must be in [-180, 180] and not 0")


def legs_to_json(legs: Sequence[Leg]) -> list[dict]:
    """The legs as JSON objects (plan.json, the log's scenario record)."""
    return [asdict(leg) for leg in legs]


def legs_from_json(items: Iterable[Mapping]) -> tuple[Leg, ...]:
    """Legs from :func:`legs_to_json`'s objects (extra keys such as start/end times are ignored)."""
    fields = Leg.__dataclass_fields__
    try:
        legs = tuple(Leg(**{k: v for k, v in dict(item).items() if k in fields}) for item in items)
    except TypeError as exc:
        raise InputError(f"legs: {exc}; regenerate the calibration run with rapt-plan shakedown") from None
    check_legs(legs)
    return legs


def check_legs(legs: Sequence[Leg]) -> None:
    """InputError unless the legs end with the one return leg."""
    if not legs or legs[-1].kind != "return" or any(leg.kind == "return" for leg in legs[:-1]):
        raise InputError("legs: a calibration run's legs end with exactly one 'return' leg")


def leg_schedule(legs: Sequence[Leg]) -> np.ndarray:
    """(len(legs) + 1,) mission seconds each leg starts at; the last entry is when the return leg must end."""
    return np.concatenate([[0.0], np.cumsum([leg.duration_s for leg in legs])])


def leg_records(legs: Sequence[Leg]) -> list[dict]:
    """Each leg with its scheduled ``start_s`` and ``end_s`` (mission seconds; the return leg's end is the
    most it may take): what a calibration run's log records (``meta/scenario``) for the fit to read."""
    t = leg_schedule(legs)
    return [{**item, "start_s": float(t[k]), "end_s": float(t[k + 1])} for k, item in enumerate(legs_to_json(legs))]


def leg_driver(legs: Sequence[Leg]):
    """``driver`` for :func:`sim.uuv.simulate.simulate`: the batch simulator flies ``legs``."""
    legs = tuple(legs)
    return lambda scen: LegAutonomy(scen, legs)


class LegAutonomy:
    """Fly ``legs`` on N vehicles of the scenarios ``scen`` (module docstring).

    It keeps the attributes the simulator, the scorer and the back-seat process read of an
    autonomy: ``goal_kind`` (return while on the last leg, waypoint before), ``return_reason``
    (complete once homeward), ``wp_aborted`` (never: it flies no waypoints); and ``leg``, the
    index of each vehicle's current leg.
    """

    def __init__(self, scen: Scenarios, legs: Sequence[Leg]):
        check_legs(legs)
        n = scen.n
        self.scen, self.mission, self.spec, self.legs = scen, scen.mission, scen.mission.vehicle, tuple(legs)
        self.starts = leg_schedule(self.legs)
        self.leg = np.zeros(n, dtype=np.int64)
        self.goal_kind = np.full(n, GOAL_WAYPOINT, dtype=np.int64)
        self.return_reason = np.zeros(n, dtype=np.int64)
        self.wp_aborted = np.zeros((n, scen.waypoints.shape[0]), dtype=bool)
        self.surfacing = np.zeros(n, dtype=bool)  # latched once the return leg surfaces
        self._rows = np.arange(n)
        self._heading_in = [self._entry_heading(i) for i in range(len(self.legs))]

    def _entry_heading(self, i: int) -> float:
        """Compass radians the vehicle is commanded on as leg ``i`` begins (a turn ramps from it)."""
        leg = self.legs[i]
        return float(np.deg2rad(leg.heading_deg - leg.turn_deg if leg.kind == "turn" else leg.heading_deg))

    def step(self, obs: Observation, dt: float, active: np.ndarray | None = None) -> Command:
        """The leg of mission time ``obs.t`` decides for every vehicle."""
        n = obs.x.shape[0]
        i = min(int(np.searchsorted(self.starts, obs.t, side="right")) - 1, len(self.legs) - 1)
        leg = self.legs[i]
        self.leg = np.full(n, i, dtype=np.int64)
        if leg.kind == "return":
            self.goal_kind = np.full(n, GOAL_RETURN, dtype=np.int64)
            self.return_reason = np.where(self.return_reason == 0, RETURN_COMPLETE, self.return_reason)
            return self._return(obs)
        heading = np.full(n, self._heading(i, obs.t - self.starts[i]))
        return Command(heading, np.full(n, float(leg.speed)), np.full(n, bool(leg.surface)))

    def _heading(self, i: int, since_s: float) -> float:
        """Compass radians commanded ``since_s`` into leg ``i``."""
        leg = self.legs[i]
        if leg.kind != "turn":
            return float(np.deg2rad(leg.heading_deg))
        rate = max(TURN_RAMP * self.spec.max_turn_rate_dps, TURN_STEP_DEG / self.mission.dt)
        ramp = rate * max(since_s, 0.0)
        turned = float(np.sign(leg.turn_deg)) * min(abs(leg.turn_deg), ramp)
        return float(wrap_angle(np.asarray(self._heading_in[i] + np.deg2rad(turned))))

    def _return(self, obs: Observation) -> Command:
        """Home over ground, crabbing against the predicted tide, slowing near it; surface inside the radius."""
        m = self.mission
        rx, ry = m.recovery
        dx, dy = rx - obs.x, ry - obs.y
        dist = np.hypot(dx, dy)
        self.surfacing |= dist <= SURFACE_WITHIN * m.recovery_radius
        ground = np.minimum(self.spec.cruise_speed, dist / ARRIVE_S)
        course = np.arctan2(dx, dy)
        ce, cn = obs.current_e, obs.current_n
        if ce is None or cn is None:
            ce, cn = tidal_current(m.current, self.scen.start_time + obs.t)
        we = ground * np.sin(course) - ce
        wn = ground * np.cos(course) - cn
        speed = np.minimum(np.hypot(we, wn), self.spec.max_speed)
        return Command(np.arctan2(we, wn), speed, self.surfacing.copy())
