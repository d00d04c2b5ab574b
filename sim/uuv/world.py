"""The simulated world of N vehicles: dynamics, current, navigation error and sensors.

This is what sits on the far side of the front-seat/back-seat interface.  The batch
simulator drives it with the autonomy in the same process; the MAVLink front-seat
simulator (:mod:`sim.uuv.ardusub.frontseat`) drives a world of one vehicle with set-points arriving
over MAVLink.  Either way :meth:`World.telemetry` is what the vehicle reports, rounded as
MAVLink carries it (:mod:`sim.uuv.interface`), and :meth:`World.advance` applies a decoded
set-point for one step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.uuv.bias import bias_arrays, compose_arrays
from sim.uuv.environment import biased_tide
from sim.uuv.interface import DEPTH_M, battery_fraction, energy_consumed_hj, report_heading, report_position
from sim.uuv.mission import Vehicle
from sim.uuv.navigation import Navigation
from sim.uuv.scenario import Scenarios
from sim.uuv.sonar import scan, sense
from sim.uuv.vehicle import VehicleState, step_vehicle

__all__ = ["World", "Telemetry", "NoiseStreams", "scenario_generators"]


@dataclass
class Telemetry:
    """One step's report of N vehicles.

    ``x, y`` are the true position at report precision (the referee's view; equal to the
    navigation estimate ``est_x, est_y`` when the run is deterministic); contact points
    are where the vehicle believes each obstacle's closest point is.
    """

    t: float
    x: np.ndarray
    y: np.ndarray
    est_x: np.ndarray
    est_y: np.ndarray
    heading: np.ndarray
    energy_hj: np.ndarray
    battery: np.ndarray
    surfaced: np.ndarray
    contact_x: np.ndarray
    contact_y: np.ndarray
    contact_distance: np.ndarray
    detected: np.ndarray
    scan: np.ndarray | None = None  # (N, beams) 360-degree ranges in metres (cm steps), when asked


def scenario_generators(X: np.ndarray, seed: int) -> list[np.random.Generator]:
    """One generator per scenario, keyed by the seed and the scenario's bytes."""
    out = []
    for row in np.asarray(X, dtype=float):
        words = np.frombuffer(np.ascontiguousarray(row).tobytes(), dtype=np.uint32)
        out.append(np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, *words.tolist()])))
    return out


class NoiseStreams:
    """Per-scenario random streams, drawn in blocks and served as one (N, 6) array per step.

    Each scenario's draws come from its own generator in a fixed order, so a scenario's
    run does not depend on the batch it is in.
    """

    PER_STEP = 6
    BLOCK = 256

    def __init__(self, rngs: list[np.random.Generator]):
        self.rngs = rngs
        self.buffer = np.empty((len(rngs), 0, self.PER_STEP))
        self.cursor = 0

    def take(self, keep: np.ndarray) -> None:
        self.rngs = [self.rngs[i] for i in keep.tolist()]
        self.buffer = self.buffer[keep]

    def next(self) -> np.ndarray:
        if self.cursor >= self.buffer.shape[1]:
            self.buffer = np.stack([g.standard_normal((self.BLOCK, self.PER_STEP)) for g in self.rngs])
            self.cursor = 0
        self.cursor += 1
        return self.buffer[:, self.cursor - 1]


class World:
    """Vehicles of the scenarios ``scen`` at their launch point, at rest, submerged.

    ``bias`` (one :class:`sim.uuv.bias.Bias`, or one per scenario) makes the vehicles behave
    like biased real ones; the autonomy never sees it.  It is composed on top of the
    mission's day bias (``Mission.execution_bias``, :func:`sim.uuv.bias.compose`).  ``scan_beams`` > 0 adds a
    360-degree range scan to the telemetry (what a learned back-seat sees, section 6.5.3).
    ``plant`` (a :class:`sim.uuv.mission.Vehicle`, default the mission's) is the vehicle that
    actually flies: its dynamics, power, battery and sensors; the autonomy keeps the mission's.
    """

    def __init__(
        self,
        scen: Scenarios,
        rngs: list[np.random.Generator] | None = None,
        bias=None,
        scan_beams: int = 0,
        plant: Vehicle | None = None,
    ):
        m = scen.mission
        self.scen, self.mission, self.spec = scen, m, m.vehicle if plant is None else plant
        n = scen.n
        lx, ly = m.launch
        heading0 = np.arctan2(m.waypoints[0][0] - lx, m.waypoints[0][1] - ly) if m.waypoints else 0.0
        self.start_wh = scen.battery0 * self.spec.battery_wh
        self.state = VehicleState.at_rest(
            np.full(n, float(lx)), np.full(n, float(ly)), np.full(n, heading0), self.start_wh.copy()
        )
        self.noise = NoiseStreams(rngs) if rngs is not None else None
        self.nav = Navigation(n, self.spec)
        self.surfaced = np.zeros(n, dtype=bool)
        self.depth = np.full(n, DEPTH_M)
        self.drift_e = np.zeros(n)
        self.drift_n = np.zeros(n)
        # the day's water and vehicle (the mission's [execution_bias]), ``bias`` relative to it
        self.bias = compose_arrays(bias_arrays(bias, n), m.execution_bias)
        self.scan_beams = int(scan_beams)

    def take(self, keep: np.ndarray) -> None:
        """Keep only the vehicles ``keep`` (finished runs are dropped from a batch)."""
        self.scen = self.scen.select(keep)
        self.state = self.state.select(keep)
        self.nav.ex, self.nav.ey, self.nav.var = self.nav.ex[keep], self.nav.ey[keep], self.nav.var[keep]
        if self.noise is not None:
            self.noise.take(keep)
        self.start_wh, self.surfaced, self.depth = self.start_wh[keep], self.surfaced[keep], self.depth[keep]
        self.drift_e, self.drift_n = self.drift_e[keep], self.drift_n[keep]
        self.bias = self.bias.select(keep)

    def telemetry(self, t: float) -> Telemetry:
        s, scen = self.state, self.scen
        qx, qy = report_position(s.x), report_position(s.y)
        qh = report_heading(s.heading)
        hj = energy_consumed_hj(self.start_wh, s.energy_wh)
        battery = battery_fraction(self.start_wh, hj, self.spec.battery_wh)
        contacts = sense(qx, qy, qh, scen.obstacle_edges, scen.barriers, self.spec)
        if self.noise is None:
            ex, ey = qx, qy
            cx, cy = report_position(contacts.x), report_position(contacts.y)
        else:  # the vehicle places what its sonar sees relative to where it thinks it is
            ex, ey = self.nav.estimate(s.x, s.y)
            ex, ey = report_position(ex), report_position(ey)
            cx = report_position(contacts.x + (ex - qx)[:, None])
            cy = report_position(contacts.y + (ey - qy)[:, None])
        ranges = (
            scan(qx, qy, qh, scen.obstacle_edges, scen.barriers, self.spec.sonar_range_m, self.scan_beams)
            if self.scan_beams
            else None
        )
        return Telemetry(
            t,
            qx,
            qy,
            ex,
            ey,
            qh,
            hj,
            battery,
            self.surfaced.copy(),
            cx,
            cy,
            contacts.distance,
            contacts.detected,
            ranges,
        )

    def advance(
        self,
        t: float,
        heading: np.ndarray,
        speed: np.ndarray,
        surface: np.ndarray,
        moving: np.ndarray,
        dt: float | None = None,
        *,
        vertical: bool = True,
    ) -> None:
        """Apply a decoded set-point to the ``moving`` vehicles for one step from time ``t``.

        ``dt`` defaults to the mission's step; the bare front-seat advances in shorter
        sub-steps so that positions move smoothly between its reports.  ``surface`` is the
        surface command, flown at the vehicle's ascent rate (:meth:`rise`); with
        ``vertical=False`` it is the vehicle's surfaced state itself (the bare front-seat
        models depth on its own, :mod:`sim.uuv.ardusub.depth`).
        """
        m = self.mission
        dt = m.dt if dt is None else float(dt)
        if vertical:
            self.rise(np.asarray(surface, dtype=bool), moving, dt)
        else:
            self.surfaced = np.asarray(surface, dtype=bool) & moving
            self.depth = np.where(self.surfaced, 0.0, DEPTH_M)
        b = self.bias
        ce, cn = biased_tide(m.current, self.scen.start_time + b.start_time + t, b)
        z = self.noise.next() if self.noise is not None else None
        if z is not None:
            # slowly varying unpredicted current: first-order Gauss-Markov, 10-minute correlation
            a = np.exp(-dt / 600.0)
            s = m.current.perturbation * np.sqrt(1 - a * a)
            self.drift_e = a * self.drift_e + s * z[:, 0]
            self.drift_n = a * self.drift_n + s * z[:, 1]
        step_vehicle(
            self.state,
            self.spec,
            heading,
            speed,
            ce + self.drift_e,
            cn + self.drift_n,
            dt,
            moving,
            speed_scale=b.speed,
            course_bias=b.heading_rad,
            energy_scale=b.battery,
            surfaced=self.surfaced,
        )
        self.nav.step(dt, self.surfaced, None if z is None else z[:, 2:])

    def rise(self, surface: np.ndarray, moving: np.ndarray, dt: float) -> None:
        """Move the ``moving`` vehicles towards the surface (``surface``) or their running depth for ``dt`` s.

        At the plant's ``ascent_rate_mps`` (the same rate down); surfaced once at the top.
        Rate 0 is instantaneous: surfaced in the very step the command asks for it.
        """
        rate = float(self.spec.ascent_rate_mps)
        if rate <= 0.0:
            self.surfaced = surface & moving
            self.depth = np.where(self.surfaced, 0.0, DEPTH_M)
            return
        up = np.maximum(self.depth - rate * dt, 0.0)
        down = np.minimum(self.depth + rate * dt, DEPTH_M)
        self.depth = np.where(moving, np.where(surface, up, down), self.depth)
        self.surfaced = surface & moving & (self.depth <= 1e-9)
