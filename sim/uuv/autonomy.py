"""The back-seat autonomy: behaviours and priorities of section 3.7.1, for N vehicles at once.

Each step the autonomy turns what the vehicle believes (navigation estimate, battery,
sonar contacts, clock) into a desired heading, speed and whether to surface:

* **Goal selection** by priority: return home (mission complete, not enough fuel, or not
  enough time) > transmission (window open and data not yet sent) > waypoints in order >
  survey of the next mission area in priority order, with loiter until its dwell time.
* **Potential field** towards the goal, repelled by sonar contacts (100 m, 120 degrees)
  and by the known no-go areas (ignored at critical battery), with a tangential term
  that slides along an obstacle — and local minima behind barriers, which the stuck
  detector resolves by aborting the goal (a waypoint abort, a skipped area).
* **Crabbing** against the predicted tidal current: the commanded through-water
  velocity is the desired ground velocity minus the current.

It is deliberately imperfect, like the dissertation's: its decisions flip with small
changes of the scenario, which is what creates performance boundaries.  The same class
drives the vectorised batch simulator and a single vehicle over MAVLink (N = 1): it
reads only observations and its own state, never the true world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.uuv.contact_memory import CONTACT_MEMORY_S, ContactMemory
from sim.uuv.environment import tidal_current
from sim.uuv.geometry import inside_rect, rect_closest_point, rect_signed_distance
from sim.uuv.scenario import Scenarios
from sim.uuv.vehicle import propulsion_power

__all__ = [
    "Autonomy",
    "Observation",
    "Command",
    "GOAL_WAYPOINT",
    "GOAL_TRANSMIT",
    "GOAL_SURVEY",
    "GOAL_RETURN",
    "RETURN_COMPLETE",
    "RETURN_FUEL",
    "RETURN_TIME",
]

GOAL_WAYPOINT, GOAL_TRANSMIT, GOAL_SURVEY, GOAL_RETURN = 0, 1, 2, 3
RETURN_NONE, RETURN_COMPLETE, RETURN_FUEL, RETURN_TIME = 0, 1, 2, 3

#: A waypoint this close to a no-go area is abandoned as soon as it becomes the goal.
WAYPOINT_ABORT_M = 60.0
#: Repulsion from known no-go areas starts at this distance.
NOGO_INFLUENCE_M = 80.0
#: A goal is abandoned when the distance to it has not shrunk by PROGRESS_M in STUCK_S.
STUCK_S = 400.0
PROGRESS_M = 20.0
#: Weights of the potential field terms (attraction has weight 1).
OBSTACLE_GAIN = 2.5
NOGO_GAIN = 2.0
SLIDE_GAIN = 2.5
#: The autonomy steers away from the operational area's edge within this distance.
OP_MARGIN_M = 60.0
#: Loiter speed as a fraction of cruise while surveying or transmitting.
LOITER_FRACTION = 0.5


@dataclass
class Observation:
    """What the back-seat sees each step (arrays over N vehicles; contacts are (N, K))."""

    t: float  # seconds since mission start
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray  # compass radians
    battery: np.ndarray  # charge fraction
    contact_x: np.ndarray
    contact_y: np.ndarray
    contact_range: np.ndarray
    detected: np.ndarray  # bool
    current_e: np.ndarray | None = None  # predicted tide (m/s); None: look it up from the tide table
    current_n: np.ndarray | None = None
    nogo_distance: np.ndarray | None = None  # (N, Z) from the estimated position; None: computed here
    scan: np.ndarray | None = None  # (N, beams) 360-degree sonar ranges (m), when the world scans
    surfaced: np.ndarray | None = None  # (N,) bool, from a real depth reading; None: surfacing is immediate


@dataclass
class Command:
    heading: np.ndarray  # compass radians, through water
    speed: np.ndarray  # m/s through water
    surface: np.ndarray  # bool


class Autonomy:
    """Behaviour state of N vehicles on the scenarios ``scen`` (see module docstring)."""

    def __init__(self, scen: Scenarios):
        m = scen.mission
        self.scen = scen
        self.mission = m
        self.spec = m.vehicle
        n, W, A = scen.n, scen.waypoints.shape[0], scen.area_rect.shape[1]
        self.n_waypoints, self.n_areas = W, A
        self.wp = np.zeros(n, dtype=np.int64)
        self.wp_aborted = np.zeros((n, W), dtype=bool)
        self.area_k = np.zeros(n, dtype=np.int64)  # position in the priority order
        self.area_aborted = np.zeros((n, A), dtype=bool)
        self.dwell = np.zeros((n, A))
        self.tx_done = np.full(n, m.transmission is None)  # nothing to send: done from the start
        self.tx_aborted = np.zeros(n, dtype=bool)
        self.tx_time = np.zeros(n)
        self.returning = np.zeros(n, dtype=bool)
        self.return_reason = np.zeros(n, dtype=np.int64)
        self.goal_kind = np.zeros(n, dtype=np.int64)
        self.best_dist = np.full(n, np.inf)
        self.since_progress = np.zeros(n)
        self.last_goal = np.full(n, -1, dtype=np.int64)
        cx = (scen.area_rect[..., 0] + scen.area_rect[..., 1]) / 2
        cy = (scen.area_rect[..., 2] + scen.area_rect[..., 3]) / 2
        self.area_cx, self.area_cy = cx, cy
        self.tx_cx = (scen.tx_rect[:, 0] + scen.tx_rect[:, 1]) / 2
        self.tx_cy = (scen.tx_rect[:, 2] + scen.tx_rect[:, 3]) / 2
        # Waypoints too close to a no-go area are abandoned on arrival as goals (known map).
        if W and scen.nogo.shape[1]:
            near = np.stack(
                [
                    np.any(rect_signed_distance(np.full(n, wx), np.full(n, wy), scen.nogo) < WAYPOINT_ABORT_M, axis=1)
                    for wx, wy in scen.waypoints
                ],
                axis=1,
            )
        else:
            near = np.zeros((n, W), dtype=bool)
        self.wp_doomed = near
        self.memory = ContactMemory(CONTACT_MEMORY_S)  # last seen sonar contacts (N, K)
        op = m.operational_area
        self._op_bounds = (op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2)
        self._rows = np.arange(n)
        self.stuck_s = STUCK_S  # seconds without progress before a goal is given up
        cruise = self.spec.cruise_speed
        self._wh_per_m = float(propulsion_power(self.spec, np.asarray(cruise))) / cruise / 3600.0

    # -- goal selection ---------------------------------------------------------------
    def _current_area(self) -> np.ndarray:
        k = np.minimum(self.area_k, max(self.n_areas - 1, 0))
        return self.scen.order[self._rows, k] if self.n_areas else np.zeros_like(k)

    def _select_goal(self, obs: Observation, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        scen, m, t = self.scen, self.mission, obs.t
        W, A = self.n_waypoints, self.n_areas
        # waypoints: skip doomed ones as they come up
        while W:
            doomed = (self.wp < W) & self.wp_doomed[self._rows, np.minimum(self.wp, W - 1)]
            if not np.any(doomed):
                break
            self.wp_aborted[self._rows[doomed], self.wp[doomed]] = True
            self.wp[doomed] += 1
        areas_left = self.area_k < A
        tx_pending = ~self.tx_done & ~self.tx_aborted & (t < scen.tx_close)
        tx_open = tx_pending & (t >= scen.tx_open)
        complete = ~areas_left & ~tx_pending & (self.wp >= W)

        # fuel and time checks: return when the trip home would eat the reserve
        rx, ry = m.recovery
        home = np.hypot(rx - obs.x, ry - obs.y)
        cruise = self.spec.cruise_speed
        energy_home = home * self._wh_per_m
        energy_left = obs.battery * self.spec.battery_wh
        low_fuel = energy_home * self.spec.reserve_factor >= energy_left
        late = t + 1.2 * home / cruise >= m.time_limit_s
        start = active & ~self.returning
        for cond, reason in ((complete, RETURN_COMPLETE), (low_fuel, RETURN_FUEL), (late, RETURN_TIME)):
            now = start & cond & ~self.returning
            self.returning |= now
            self.return_reason[now] = reason

        kind = np.full(self.scen.n, GOAL_SURVEY)
        kind = np.where(self.wp < W, GOAL_WAYPOINT, kind)
        kind = np.where(tx_open, GOAL_TRANSMIT, kind)
        kind = np.where(self.returning, GOAL_RETURN, kind)
        # nothing left but a transmission window that has not opened yet: wait near the area
        idle = (kind == GOAL_SURVEY) & ~areas_left
        kind = np.where(idle & tx_pending, GOAL_TRANSMIT, kind)

        area = self._current_area()
        gx = np.full(self.scen.n, float(rx))
        gy = np.full(self.scen.n, float(ry))
        if W:
            w = np.minimum(self.wp, W - 1)
            gx = np.where(kind == GOAL_WAYPOINT, scen.waypoints[w, 0], gx)
            gy = np.where(kind == GOAL_WAYPOINT, scen.waypoints[w, 1], gy)
        if A:
            gx = np.where(kind == GOAL_SURVEY, self.area_cx[self._rows, area], gx)
            gy = np.where(kind == GOAL_SURVEY, self.area_cy[self._rows, area], gy)
        gx = np.where(kind == GOAL_TRANSMIT, self.tx_cx, gx)
        gy = np.where(kind == GOAL_TRANSMIT, self.tx_cy, gy)
        self.goal_kind = kind
        return kind, gx, gy

    @staticmethod
    def _nogo_push(
        x: np.ndarray, y: np.ndarray, d: np.ndarray, gx: np.ndarray, gy: np.ndarray, nogo: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Push from the known no-go areas: away from the closest point, out of an area, and
        along the area round its nearer end (the map gives its extent, unlike a sonar contact)."""
        cx, cy = rect_closest_point(x, y, nogo)
        dx, dy = x[:, None] - cx, y[:, None] - cy
        r = np.maximum(np.hypot(dx, dy), 1e-6)
        inside = d <= 0
        strength = np.where(inside, 2.0, np.clip((NOGO_INFLUENCE_M - d) / NOGO_INFLUENCE_M, 0.0, 1.0))
        strength = np.where(inside_rect(gx, gy, nogo), 0.0, strength)  # never repel from the goal's own area
        # inside an area the closest point is the vehicle itself: push out east or west
        mx, my = (nogo[..., 0] + nogo[..., 1]) / 2, (nogo[..., 2] + nogo[..., 3]) / 2
        ux = np.where(inside, np.where(x[:, None] >= mx, 1.0, -1.0), dx / r)
        uy = np.where(inside, 0.0, dy / r)
        # round the end away from the area's centre: tangent side from which side of the
        # vehicle-goal line the centre lies
        ax, ay = gx[:, None] - x[:, None], gy[:, None] - y[:, None]
        side = np.sign(ax * (my - y[:, None]) - ay * (mx - x[:, None]))
        side = np.where(side == 0, 1.0, side)
        slide = np.where(inside, 0.0, strength) * SLIDE_GAIN
        px = NOGO_GAIN * strength * ux - slide * side * uy
        py = NOGO_GAIN * strength * uy + slide * side * ux
        return px.sum(axis=1), py.sum(axis=1)

    # -- one decision ------------------------------------------------------------------
    def step(self, obs: Observation, dt: float, active: np.ndarray | None = None) -> Command:
        """Decide for every vehicle; ``active`` masks vehicles whose run has ended."""
        n = self.scen.n
        active = np.ones(n, dtype=bool) if active is None else active
        kind, gx, gy = self._select_goal(obs, active)
        area = self._current_area()
        in_area = self._survey(obs, dt, kind, area, active)
        in_tx, sending = self._transmit(obs, dt, kind, active)
        self._arrive(obs, kind, gx, gy, active)
        self._give_up_when_stuck(obs, dt, kind, gx, gy, area, in_area | in_tx, active)
        fx, fy = self._potential_field(obs, gx, gy)
        return self._command(obs, fx, fy, kind, in_area, in_tx, sending)

    # -- behaviours ----------------------------------------------------------------------
    def _survey(
        self, obs: Observation, dt: float, kind: np.ndarray, area: np.ndarray, active: np.ndarray
    ) -> np.ndarray:
        """Loiter progress in the current mission area (what the vehicle believes); returns who is in it."""
        scen = self.scen
        in_area = np.zeros(scen.n, dtype=bool)
        if self.n_areas:
            rect = scen.area_rect[self._rows, area]
            in_area = inside_rect(obs.x, obs.y, rect[:, None, :])[:, 0] & (kind == GOAL_SURVEY) & active
            self.dwell[self._rows[in_area], area[in_area]] += dt
            done = in_area & (self.dwell[self._rows, area] >= scen.area_dwell[self._rows, area])
            self.area_k[done] += 1
        return in_area

    def _transmit(
        self, obs: Observation, dt: float, kind: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Transmission progress: who is in the area, and who is sending (in it while the window is open)."""
        scen, n = self.scen, self.scen.n
        in_tx = np.zeros(n, dtype=bool)
        tx = self.mission.transmission
        if tx is not None:
            in_tx = inside_rect(obs.x, obs.y, scen.tx_rect[:, None, :])[:, 0] & (kind == GOAL_TRANSMIT) & active
            window = (obs.t >= scen.tx_open) & (obs.t < scen.tx_close)
            sending = in_tx & window  # on the surface, or rising to it
            # a real vehicle takes seconds to rise: its data goes out only once it is up
            sent = sending if obs.surfaced is None else sending & obs.surfaced
            self.tx_time[sent] += dt
            self.tx_done |= self.tx_time >= tx.duration_s
        else:
            sending = np.zeros(n, dtype=bool)
        return in_tx, sending

    def _arrive(self, obs: Observation, kind: np.ndarray, gx: np.ndarray, gy: np.ndarray, active: np.ndarray) -> None:
        """Waypoint arrival: the next waypoint becomes the goal."""
        if self.n_waypoints:
            arrived = (kind == GOAL_WAYPOINT) & (np.hypot(gx - obs.x, gy - obs.y) <= self.mission.waypoint_radius)
            self.wp[arrived & active] += 1

    def _give_up_when_stuck(
        self,
        obs: Observation,
        dt: float,
        kind: np.ndarray,
        gx: np.ndarray,
        gy: np.ndarray,
        area: np.ndarray,
        loitering: np.ndarray,
        active: np.ndarray,
    ) -> None:
        """Stuck detection: abandon a goal (never the way home) not approached by PROGRESS_M in stuck_s."""
        A = self.n_areas
        dist = np.hypot(gx - obs.x, gy - obs.y)
        goal_id = kind * 1000 + np.where(kind == GOAL_WAYPOINT, self.wp, np.where(kind == GOAL_SURVEY, area, 0))
        changed = goal_id != self.last_goal
        self.last_goal = goal_id
        self.best_dist = np.where(changed, dist, self.best_dist)
        self.since_progress = np.where(changed, 0.0, self.since_progress)
        progressed = dist < self.best_dist - PROGRESS_M
        self.best_dist = np.where(progressed, dist, self.best_dist)
        self.since_progress = np.where(progressed | loitering, 0.0, self.since_progress + dt)
        stuck = active & (self.since_progress >= self.stuck_s) & (kind != GOAL_RETURN)
        if np.any(stuck):
            sw = stuck & (kind == GOAL_WAYPOINT)
            self.wp_aborted[self._rows[sw], np.minimum(self.wp[sw], self.n_waypoints - 1)] = True
            self.wp[sw] += 1
            sa = stuck & (kind == GOAL_SURVEY) & (self.area_k < A)
            if A:
                self.area_aborted[self._rows[sa], area[sa]] = True
            self.area_k[sa] += 1
            self.tx_aborted |= stuck & (kind == GOAL_TRANSMIT)
            self.since_progress[stuck] = 0.0

    # -- potential field over ground -------------------------------------------------------
    def _potential_field(self, obs: Observation, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Attraction to the goal plus the pushes of sonar contacts, no-go areas and the operational area's edge."""
        ax, ay = gx - obs.x, gy - obs.y
        norm = np.maximum(np.hypot(ax, ay), 1e-9)
        ax, ay = ax / norm, ay / norm
        fx, fy = ax.copy(), ay.copy()
        self._avoid_contacts(obs, ax, ay, fx, fy)
        self._avoid_nogo(obs, gx, gy, fx, fy)
        # keep off the edge of the operational area (known): push inwards within OP_MARGIN_M
        x0, x1, y0, y1 = self._op_bounds
        fx += NOGO_GAIN * (
            np.clip(1 - (obs.x - x0) / OP_MARGIN_M, 0, 1) - np.clip(1 - (x1 - obs.x) / OP_MARGIN_M, 0, 1)
        )
        fy += NOGO_GAIN * (
            np.clip(1 - (obs.y - y0) / OP_MARGIN_M, 0, 1) - np.clip(1 - (y1 - obs.y) / OP_MARGIN_M, 0, 1)
        )
        return fx, fy

    def _avoid_contacts(self, obs: Observation, ax: np.ndarray, ay: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> None:
        """Add (in place) the push of remembered sonar contacts to ``fx``, ``fy``; ``ax``, ``ay`` point to the goal."""
        if not obs.contact_x.shape[1]:
            return
        known = self.memory.update(obs.t, obs.contact_x, obs.contact_y, obs.detected)
        mem_x, mem_y = self.memory.x, self.memory.y
        assert mem_x is not None and mem_y is not None, "update() has stored this step's contacts"
        rows = np.flatnonzero(np.any(known, axis=1))
        if rows.size:  # only vehicles with a (remembered) sonar contact
            d0 = self.spec.sonar_range_m
            dx = obs.x[rows, None] - mem_x[rows]
            dy = obs.y[rows, None] - mem_y[rows]
            r = np.maximum(np.hypot(dx, dy), 1.0)
            mag = np.where(known[rows], OBSTACLE_GAIN * np.clip((d0 - r) / d0, 0.0, 1.0) ** 2 * d0 / r, 0.0)
            px, py = (mag * dx / r).sum(axis=1), (mag * dy / r).sum(axis=1)
            # slide along the obstacle, starting as soon as it is seen (linear in range): of the
            # two tangents take the one leading towards the goal, so the vehicle keeps going round
            # the side it is on; an obstacle square across the path is a local minimum
            lin = np.where(known[rows], np.clip((d0 - r) / d0, 0.0, 1.0), 0.0)
            lx, ly = (lin * dx / r).sum(axis=1), (lin * dy / r).sum(axis=1)
            side = np.sign(ay[rows] * lx - ax[rows] * ly)
            side = np.where(side == 0, 1.0, side)
            fx[rows] += px - SLIDE_GAIN * side * ly
            fy[rows] += py + SLIDE_GAIN * side * lx

    def _avoid_nogo(self, obs: Observation, gx: np.ndarray, gy: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> None:
        """Add (in place) the push of known no-go areas near a vehicle, unless its battery is critical."""
        scen = self.scen
        if scen.nogo.shape[1]:
            obey = obs.battery > self.spec.critical_battery  # critical battery overrides no-go avoidance
            d = obs.nogo_distance if obs.nogo_distance is not None else rect_signed_distance(obs.x, obs.y, scen.nogo)
            rows = np.flatnonzero(np.any(d < NOGO_INFLUENCE_M, axis=1) & obey)  # only those near an area
            if rows.size:
                fx_n, fy_n = self._nogo_push(
                    obs.x[rows], obs.y[rows], d[rows], gx[rows], gy[rows], self.scen.nogo[rows]
                )
                fx[rows] += fx_n
                fy[rows] += fy_n

    # -- the command -------------------------------------------------------------------------
    def _command(
        self,
        obs: Observation,
        fx: np.ndarray,
        fy: np.ndarray,
        kind: np.ndarray,
        in_area: np.ndarray,
        in_tx: np.ndarray,
        sending: np.ndarray,
    ) -> Command:
        """Heading and speed through water along the field (crabbing against the predicted current); loiter
        slowly in an area or at home, and surface to send or to be picked up."""
        spec = self.spec
        course = np.arctan2(fx, fy)
        # home: surface at the recovery point and wait to be picked up
        rx, ry = self.mission.recovery
        at_home = self.returning & (np.hypot(obs.x - rx, obs.y - ry) <= self.mission.recovery_radius)
        loiter = (kind == GOAL_SURVEY) & in_area | (kind == GOAL_TRANSMIT) & in_tx | at_home
        speed = np.where(loiter, LOITER_FRACTION * spec.cruise_speed, spec.cruise_speed)
        # crabbing: through-water velocity = desired ground velocity - predicted current
        ce, cn = obs.current_e, obs.current_n
        if ce is None:
            ce, cn = tidal_current(self.mission.current, self.scen.start_time + obs.t)
        we = speed * np.sin(course) - ce
        wn = speed * np.cos(course) - cn
        heading = np.arctan2(we, wn)
        water_speed = np.minimum(np.hypot(we, wn), spec.max_speed)
        return Command(heading, water_speed, sending | at_home)
