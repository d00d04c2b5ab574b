"""A torpedo UUV's 3-DOF (surge, sway, yaw) manoeuvring model with its speed/heading autopilot.

First-order surge and yaw-rate responses, a turn-rate limit and sway induced by turning
are what make a torpedo vehicle overshoot and drift off a potential-field path; battery
drain grows with the cube of speed (a torpedo's; ``Vehicle.power_exponent`` sets another
power of speed, e.g. about 1 for a thruster vehicle), which makes the fuel decisions of
the autonomy bite.
Headings are compass radians (0 north, clockwise); positions x east, y north in metres.
Vectorised over scenarios: every array is (N,).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sim.uuv.angles import wrap_angle
from sim.uuv.mission import Vehicle

__all__ = ["VehicleState", "step_vehicle", "propulsion_power", "reached_speed", "surface_limited"]

#: Sideslip per unit of (speed x yaw rate): a few degrees of crab angle in a hard turn.
SWAY_COUPLING = 0.8
#: Seconds to close a heading error (the autopilot's proportional gain is 1/this): the
#: default of ``Vehicle.heading_time_s``, a torpedo's gentle heading loop (a thruster
#: vehicle's autopilot closes an error far sooner, up to its turn-rate limit).
HEADING_TIME_S = 4.0


@dataclass
class VehicleState:
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    surge: np.ndarray
    sway: np.ndarray
    yaw_rate: np.ndarray
    energy_wh: np.ndarray
    # a vector-controlled vehicle's through-water velocity (east, north), its fast and slow parts;
    # zero and unused under surge control
    fast_e: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fast_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slow_e: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slow_n: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        for name in ("fast_e", "fast_n", "slow_e", "slow_n"):
            if getattr(self, name).shape != np.shape(self.x):
                setattr(self, name, np.zeros_like(self.x, dtype=float))

    def set_water_velocity(
        self, spec: Vehicle, ve: np.ndarray, vn: np.ndarray, slow: tuple[np.ndarray, np.ndarray] | None = None
    ) -> None:
        """Start a vector-controlled vehicle moving through water at (``ve``, ``vn``) m/s: its slow
        part ``slow`` (east, north) when known, else settled (``spec.slow_share`` of the velocity),
        the fast part the rest."""
        ve, vn = np.asarray(ve, dtype=float), np.asarray(vn, dtype=float)
        if slow is None:
            slow = (spec.slow_share * ve, spec.slow_share * vn)
        self.slow_e, self.slow_n = np.asarray(slow[0], dtype=float), np.asarray(slow[1], dtype=float)
        self.fast_e, self.fast_n = ve - self.slow_e, vn - self.slow_n

    @classmethod
    def at_rest(cls, x: np.ndarray, y: np.ndarray, heading: np.ndarray, energy_wh: np.ndarray) -> VehicleState:
        z = np.zeros_like(np.asarray(x, dtype=float))
        return cls(
            np.array(x, float),
            np.array(y, float),
            np.array(heading, float),
            z.copy(),
            z.copy(),
            z.copy(),
            np.array(energy_wh, float),
        )

    def select(self, rows: np.ndarray) -> VehicleState:
        return VehicleState(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))


def propulsion_power(spec: Vehicle, speed: np.ndarray) -> np.ndarray:
    """Electrical power in W at a through-water speed: the hotel load plus ``drag_w`` times
    (speed / cruise speed) to the vehicle's ``power_exponent`` (3, cubic drag, by default)."""
    return spec.hotel_w + spec.drag_w * (np.abs(speed) / spec.cruise_speed) ** spec.power_exponent


def reached_speed(spec: Vehicle, speed_cmd: np.ndarray | float) -> np.ndarray:
    """The through-water speed the speed loop settles at for a commanded speed (negative: 0).

    ``spec.speed_curve`` when the vehicle has one (interpolated from (0, 0), flat beyond its
    last knot), else ``speed_gain`` times the command, at most ``max_speed``.  A curve given as
    an (N, K, 2) array is one curve per vehicle on shared commands (a batched replay's trials).
    """
    cmd = np.maximum(np.asarray(speed_cmd, dtype=float), 0.0)
    if len(spec.speed_curve):
        knots = np.asarray(spec.speed_curve, dtype=float)
        if knots.ndim == 3:
            return _interp_rows(cmd, knots[0, :, 0], knots[:, :, 1])
        return np.interp(cmd, np.concatenate([[0.0], knots[:, 0]]), np.concatenate([[0.0], knots[:, 1]]))
    return np.minimum(spec.speed_gain * cmd, spec.max_speed)


def _interp_rows(cmd: np.ndarray, commands: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Each vehicle's own curve (``speeds`` (N, K) on ``commands`` (K,)) at its command, from (0, 0), flat beyond."""
    xp = np.concatenate([[0.0], commands])
    fp = np.concatenate([np.zeros((speeds.shape[0], 1)), speeds], axis=1)
    cmd = np.broadcast_to(cmd, (speeds.shape[0],))
    i = np.clip(np.searchsorted(xp, cmd, side="right"), 1, xp.size - 1)
    w = np.clip((cmd - xp[i - 1]) / (xp[i] - xp[i - 1]), 0.0, 1.0)
    rows = np.arange(speeds.shape[0])
    return fp[rows, i - 1] + w * (fp[rows, i] - fp[rows, i - 1])


def surface_limited(spec: Vehicle, target: np.ndarray, surfaced: np.ndarray | None) -> np.ndarray:
    """``target`` speeds held to ``spec.surface_max_speed`` where ``surfaced`` (no limit when it is 0 or None)."""
    limit = np.asarray(spec.surface_max_speed)
    if surfaced is None or np.all(limit <= 0):
        return target
    return np.where(surfaced & (limit > 0), np.minimum(target, limit), target)


def step_vehicle(
    s: VehicleState,
    spec: Vehicle,
    heading_cmd: np.ndarray,
    speed_cmd: np.ndarray,
    current_e: np.ndarray,
    current_n: np.ndarray,
    dt: float | np.ndarray,
    moving: np.ndarray,
    *,
    speed_scale=1.0,
    course_bias=0.0,
    energy_scale=1.0,
    surfaced: np.ndarray | None = None,
) -> None:
    """Advance every ``moving`` vehicle by ``dt`` seconds (one, or one per vehicle) in place; the others stay frozen.

    Execution bias (:mod:`sim.uuv.bias`): ``speed_scale`` multiplies the speed the vehicle
    achieves, ``course_bias`` (radians) turns its track through water clockwise of its
    bow, ``energy_scale`` divides the charge drawn.  The defaults change nothing.
    ``surfaced`` (per vehicle; None: all submerged) applies the vehicle's surface terms:
    at most ``spec.surface_max_speed`` (when > 0) and ``spec.surface_power_w`` more draw.
    """
    rmax = np.deg2rad(spec.max_turn_rate_dps)
    err = wrap_angle(heading_cmd - s.heading)
    r_des = np.clip(err / spec.heading_time_s, -rmax, rmax)
    a_r = 1.0 - np.exp(-dt / spec.yaw_time_constant_s)
    a_u = 1.0 - np.exp(-dt / spec.surge_time_constant_s)
    a_v = 1.0 - np.exp(-dt * spec.sway_damping)
    r = s.yaw_rate + (r_des - s.yaw_rate) * a_r
    target = surface_limited(spec, reached_speed(spec, speed_cmd), surfaced)
    psi = wrap_angle(s.heading + r * dt)
    if spec.velocity_control == "vector":
        fast_e, fast_n, slow_e, slow_n, u, v, water = _vector_velocity(
            s, spec, heading_cmd + course_bias, target * speed_scale, psi, a_u, dt
        )
        ve, vn = fast_e + slow_e + current_e, fast_n + slow_n + current_n
    else:
        u = s.surge + (target * speed_scale - s.surge) * a_u
        v = s.sway + (-SWAY_COUPLING * u * r - s.sway) * a_v
        course = psi + course_bias
        sin, cos = np.sin(course), np.cos(course)
        ve = u * sin + v * cos + current_e
        vn = u * cos - v * sin + current_n
        water = u
    power = propulsion_power(spec, water)
    if surfaced is not None and np.any(np.asarray(spec.surface_power_w) != 0):
        power = power + np.where(surfaced, spec.surface_power_w, 0.0)
    m = moving
    s.x = np.where(m, s.x + ve * dt, s.x)
    s.y = np.where(m, s.y + vn * dt, s.y)
    s.heading = np.where(m, psi, s.heading)
    s.surge = np.where(m, u, s.surge)
    s.sway = np.where(m, v, s.sway)
    s.yaw_rate = np.where(m, r, s.yaw_rate)
    if spec.velocity_control == "vector":
        s.fast_e, s.fast_n = np.where(m, fast_e, s.fast_e), np.where(m, fast_n, s.fast_n)
        s.slow_e, s.slow_n = np.where(m, slow_e, s.slow_e), np.where(m, slow_n, s.slow_n)
    s.energy_wh = np.where(m, s.energy_wh - power * dt / 3600.0 / energy_scale, s.energy_wh)


def _vector_velocity(s: VehicleState, spec: Vehicle, course: np.ndarray, speed: np.ndarray, psi, a_fast, dt):
    """A vector speed loop's step: the fast and slow parts of the through-water velocity towards
    ``speed`` along ``course``, the surge and sway they make on heading ``psi``, and their speed."""
    te, tn = speed * np.sin(course), speed * np.cos(course)
    share = spec.slow_share
    a_slow = 1.0 - np.exp(-dt / spec.slow_time_constant_s)
    fast_e = s.fast_e + ((1.0 - share) * te - s.fast_e) * a_fast
    fast_n = s.fast_n + ((1.0 - share) * tn - s.fast_n) * a_fast
    slow_e = s.slow_e + (share * te - s.slow_e) * a_slow
    slow_n = s.slow_n + (share * tn - s.slow_n) * a_slow
    we, wn = fast_e + slow_e, fast_n + slow_n
    sin, cos = np.sin(psi), np.cos(psi)
    return fast_e, fast_n, slow_e, slow_n, we * sin + wn * cos, we * cos - wn * sin, np.hypot(we, wn)
