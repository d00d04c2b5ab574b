"""The back-seat autonomy as a process on the bus: telemetry in, set-points out.

It runs the very autonomy of the batch simulator (:class:`sim.uuv.autonomy.Autonomy`, one
vehicle) on what the front-seat reports over MAVLink, relayed by the bridge on Zenoh, and
publishes each set-point under its source name.  Two pacings:

* ``"lockstep"`` (our simulated front-seat): it gathers one step's telemetry until
  SYSTEM_TIME closes it and decides once per step (a repeated step gets the same answer
  again); the simulator waits for the answer.
* ``"vehicle"`` (a real vehicle, or the simulated one as a bare autopilot): the vehicle
  streams at its own rates and keeps moving.  The back-seat decides every ``mission.dt``
  of the vehicle's own clock (``time_boot_ms``), on the first position report of each
  period and the latest of everything else (:class:`planner.common.telemetry.VehicleTelemetry`),
  from the scenario clock's start (``meta/clock``).  Late, repeated and out-of-order
  reports are dropped and counted, periods without a report are counted as missed, and a
  decision whose inputs are older than ``stale_s`` is not taken: the back-seat stops
  commanding and the vehicle's own set-point timeout (and our watchdog) act.  Decisions
  depend on the stream alone, not on wall time, so the same telemetry gives the same
  decisions at any simulator speed-up.  Depth is a real state there: the set-point holds
  the mission depth with a proportional vertical rate (:func:`sim.uuv.interface.depth_rate`).  Whether that set-point reaches the
vehicle is the bus's choice (the ``control/active`` key), so another autonomy can fly
while this one's commands are still recorded.  It also publishes its own account of the
run — aborted waypoints, why it turned home — which no track shows.

With a trained surrogate (:class:`sim.uuv.imitation.surrogate.Surrogate`) the same process
flies the learned policy instead, on the features of section 6.5.3; the 360-beam scan
arrives as five OBSTACLE_DISTANCE messages per step.

This module is where planner wires ``sim`` to ``bridge``: neither imports the other.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.service import Service  # noqa: E402
from bridge.session import receive, undeclare  # noqa: E402
from planner.common.telemetry import KINDS, VIRTUAL_BATTERY_ID, FrameDecoder, VehicleTelemetry  # noqa: E402
from rapt.errors import InputError  # noqa: E402
from sim.uuv.autonomy import GOAL_RETURN, Autonomy, Observation  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.interface import battery_fraction, depth_rate, encode_command  # noqa: E402
from sim.uuv.legs import LegAutonomy  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402

__all__ = ["BackSeat", "BackSeatStats", "DecisionClock", "PACINGS"]

#: What a lock-step back-seat reads of the stream.
LOCKSTEP_KINDS = (
    "SYSTEM_TIME",
    "LOCAL_POSITION_NED",
    "ATTITUDE",
    "BATTERY_STATUS",
    "OBSTACLE_DISTANCE_3D",
    "OBSTACLE_DISTANCE",
)
#: How the back-seat is timed (module docstring).
PACINGS = ("lockstep", "vehicle")


class BackSeatStats:
    """What the back-seat did: decisions, and the ones it could not take."""

    def __init__(self) -> None:
        self.decisions = 0
        self.missed = 0  # decision periods with no position report at all
        self.stale = 0  # decisions not taken: an input older than stale_s
        self.refreshes = 0  # the last set-point re-sent within its period
        self.latency_s: list[float] = []  # report received -> set-point published, wall seconds
        self.input_age_ms: list[int] = []  # the oldest input of each decision, vehicle ms
        self.ticks: list[int] = []  # time_boot_ms of the report each decision was taken on

    def as_dict(self) -> dict:
        lat = np.asarray(self.latency_s) * 1000.0
        age = np.asarray(self.input_age_ms, dtype=float)
        return {
            "decisions": self.decisions,
            "missed": self.missed,
            "stale": self.stale,
            "refreshes": self.refreshes,
            "latency_ms_p50": float(np.percentile(lat, 50)) if lat.size else None,
            "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else None,
            "input_age_ms_max": float(age.max()) if age.size else None,
        }


class DecisionClock:
    """When a vehicle-paced back-seat decides: every ``period_ms`` of the vehicle's clock from ``start_ms``.

    Pure bookkeeping on report times, so decisions depend on the telemetry alone.  A report at
    or after the next decision time triggers a decision; periods that passed with no report
    are counted as missed.
    """

    def __init__(self, start_ms: int, period_ms: int):
        if period_ms <= 0:
            raise InputError(f"period_ms: expected > 0, got {period_ms}")
        self.start_ms, self.period_ms = int(start_ms), int(period_ms)
        self.next_ms = self.start_ms
        self.missed = 0

    def due(self, t_ms: int) -> bool:
        """Whether a report stamped ``t_ms`` opens a decision (and advance the clock if so)."""
        if t_ms < self.next_ms:
            return False
        skipped = (t_ms - self.next_ms) // self.period_ms
        self.missed += int(skipped)
        self.next_ms += int(skipped + 1) * self.period_ms
        return True


class BackSeat(Service):
    """Fly scenario ``u`` of ``mission`` from the bus of ``session`` as ``source``.

    ``pacing`` is ``"lockstep"`` or ``"vehicle"`` (module docstring).  In vehicle pacing the
    battery read is the virtual fuel gauge's (BATTERY_STATUS id
    :data:`~planner.common.telemetry.VIRTUAL_BATTERY_ID`) unless ``battery_id`` says otherwise, and
    the scenario clock starts at :meth:`begin` or at the ``meta/clock`` key's ``start_ms``.
    ``legs`` (a calibration run's, :mod:`sim.uuv.legs`) fly in place of the mission's autonomy.
    The bus entities are declared at construction; :meth:`start` starts the loop's thread and
    :meth:`close` stops it and undeclares them (the session is left open).
    """

    _what = "back-seat"

    def __init__(
        self,
        session,
        vehicle: str,
        mission: Mission,
        u,
        source: str = keys.DEFAULT_ACTIVE,
        surrogate=None,
        *,
        pacing: str = "lockstep",
        stale_s: float | None = None,
        battery_id: int = VIRTUAL_BATTERY_ID,
        refresh_s: float = 1.0,
        legs: tuple = (),
    ):
        super().__init__()
        if pacing not in PACINGS:
            raise InputError(f"pacing: expected one of {', '.join(PACINGS)}, got {pacing!r}")
        scen = make_scenarios(mission, np.asarray(u, dtype=float).reshape(1, -1))
        if not scen.valid[0]:
            raise InputError(f"scenario: invalid for mission '{mission.name}' ({scen.invalid_reason[0]})")
        self.mission, self.scen, self.vehicle, self.source, self.pacing = mission, scen, vehicle, source, pacing
        if legs and surrogate is not None:
            raise InputError("legs: a calibration run flies its own legs, not a surrogate")
        if surrogate is not None:
            surrogate.check(mission)
            if pacing == "vehicle" and surrogate.spec.beams:
                raise InputError("surrogate: a scan-fed surrogate needs the simulator's sonar scan; fly it lock-step")
            self.autonomy = surrogate.autonomy(scen)
            self.beams = surrogate.spec.beams
        elif legs:  # a calibration run: its scripted legs (sim.uuv.legs) fly instead of the mission's autonomy
            self.autonomy = LegAutonomy(scen, legs)
            self.beams = 0
        else:
            self.autonomy = Autonomy(scen)
            self.beams = 0
        self.start_wh = scen.battery0 * mission.vehicle.battery_wh
        self.n_contacts = scen.obstacles.shape[1] + scen.barriers.shape[1]
        self.period_ms = int(round(mission.dt * 1000))
        self.stale_ms = int(round((stale_s if stale_s is not None else 2 * mission.dt) * 1000))
        self.refresh_ms = int(round(refresh_s * 1000))
        self.telemetry = VehicleTelemetry(LocalFrame(mission.origin_lat, mission.origin_lon), battery_id)
        self.clock: DecisionClock | None = None
        self.stats = BackSeatStats()
        self.session = session
        self._decoder = FrameDecoder(KINDS if pacing == "vehicle" else LOCKSTEP_KINDS)
        self._tick: dict = {}
        self._answered: dict[int, dict] = {}
        self._last_answer: dict | None = None
        self._last_decision_ms = -1
        self._last_sent_ms = -1
        self.last_tick_ms = -1
        self.steps = 0
        self._sub = session.declare_subscriber(keys.raw(vehicle))  # FIFO channel, read by our thread
        # the clock arrives once, by callback: parsing it is all the callback does (no Zenoh call, no wait)
        self._clock_sub = (
            session.declare_subscriber(keys.meta(vehicle, "clock"), self._on_clock) if pacing == "vehicle" else None
        )
        self._pub = session.declare_publisher(keys.command(vehicle, source))
        self._status = session.declare_publisher(keys.status(vehicle, source))
        self._token = session.liveliness().declare_token(keys.alive(vehicle, source))

    def begin(self, start_ms: int) -> None:
        """Start the scenario clock at the vehicle's ``time_boot_ms`` = ``start_ms`` (vehicle pacing)."""
        self.clock = DecisionClock(start_ms, self.period_ms)

    def _open(self) -> None:
        self._spawn(f"backseat-{self.source}", self._run)

    def _shutdown(self) -> None:
        undeclare(self._sub)  # ends the loop's receive()
        self._join(self._threads, timeout=5)
        undeclare(self._clock_sub, self._pub, self._status, self._token)

    # -- the loop --------------------------------------------------------------------
    def _run(self) -> None:
        on_message = self._on_message if self.pacing == "lockstep" else self._on_report
        for sample in receive(self._sub):
            received = time.perf_counter()
            for msg in self._decoder.decode(sample.payload.to_bytes()):
                on_message(msg, received)

    def _on_clock(self, sample) -> None:
        if self.clock is not None:
            return
        try:
            start_ms = int(json.loads(sample.payload.to_bytes())["start_ms"])
        except (ValueError, KeyError, TypeError):
            return
        self.begin(start_ms)

    # -- lock-step ---------------------------------------------------------------------
    def _on_message(self, msg, received: float = 0.0) -> None:
        kind = msg.get_type()
        if kind == "SYSTEM_TIME":
            self._decide(int(msg.time_boot_ms))
            self._tick = {}
        elif kind == "OBSTACLE_DISTANCE_3D":
            self._tick.setdefault("contacts", {})[int(msg.obstacle_id)] = (float(msg.y), float(msg.x))
        elif kind == "OBSTACLE_DISTANCE" and self.beams and msg.frame == mavlink.MAV_FRAME_BODY_FRD:
            scan = self._tick.setdefault("scan", np.full(self.beams, np.nan))
            start = int(round(msg.angle_offset / msg.increment_f)) if msg.increment_f > 0 else 0
            cm = np.asarray(msg.distances, dtype=float)[: max(0, min(len(msg.distances), self.beams - start))]
            scan[start : start + cm.size] = cm / 100.0
        elif kind in ("LOCAL_POSITION_NED", "ATTITUDE", "BATTERY_STATUS"):
            self._tick[kind] = msg

    def _decide(self, tick_ms: int) -> None:
        if tick_ms in self._answered:  # the front-seat repeated a step: same answer again
            self._pub.put(json.dumps(self._answered[tick_ms]))
            return
        needed = ("LOCAL_POSITION_NED", "ATTITUDE", "BATTERY_STATUS") + (("scan",) if self.beams else ())
        if (
            tick_ms < self.last_tick_ms
            or not all(k in self._tick for k in needed)
            or (self.beams and np.isnan(self._tick["scan"]).any())
        ):
            return  # a stale or incomplete step (joined mid-step): wait for the next one
        obs = self._observation(tick_ms)
        cmd = self.autonomy.step(obs, self.mission.dt, np.ones(1, dtype=bool))
        vx, vy, vz, yaw = encode_command(cmd.heading, cmd.speed, cmd.surface)
        answer = {"tick_ms": tick_ms, "vx": float(vx[0]), "vy": float(vy[0]), "vz": float(vz[0]), "yaw": float(yaw[0])}
        self._answered = {tick_ms: answer}
        self.last_tick_ms = tick_ms
        self.steps += 1
        self._pub.put(json.dumps(answer))
        self._publish_status(tick_ms)

    def _observation(self, tick_ms: int) -> Observation:
        lp, att, bat = self._tick["LOCAL_POSITION_NED"], self._tick["ATTITUDE"], self._tick["BATTERY_STATUS"]
        k = self.n_contacts
        cx, cy, seen = np.zeros((1, k)), np.zeros((1, k)), np.zeros((1, k), dtype=bool)
        for j, (east, north) in self._tick.get("contacts", {}).items():
            if 0 <= j < k:
                cx[0, j], cy[0, j], seen[0, j] = east, north, True
        battery = battery_fraction(self.start_wh, np.array([bat.energy_consumed]), self.mission.vehicle.battery_wh)
        scan = self._tick["scan"][None, :] if self.beams else None
        return Observation(
            tick_ms / 1000.0,
            np.array([float(lp.y)]),
            np.array([float(lp.x)]),
            np.array([float(att.yaw)]),
            battery,
            cx,
            cy,
            np.zeros((1, k)),
            seen,
            scan=scan,
        )

    # -- vehicle-paced -------------------------------------------------------------------
    def _on_report(self, msg, received: float) -> None:
        tel = self.telemetry
        if tel.add(msg) != "position" or self.clock is None:
            return
        pose = tel.pose
        assert pose is not None, "a position report sets the pose"
        if self.clock.due(pose.time_ms):
            self.stats.missed = self.clock.missed
            self._decide_paced(pose, received)
        elif (
            self._last_answer is not None
            and pose.time_ms - self._last_sent_ms >= self.refresh_ms
            and pose.time_ms - self._last_decision_ms <= self.stale_ms
        ):  # keep the vehicle's set-point alive within the period (ArduSub drops it after 3 s)
            self._pub.put(json.dumps(self._last_answer))
            self._last_sent_ms = pose.time_ms
            self.stats.refreshes += 1

    def _decide_paced(self, pose, received: float) -> None:
        tel, t_ms = self.telemetry, pose.time_ms
        age = max(t_ms - pose.heading_ms, t_ms - tel.energy_ms if tel.energy_hj is not None else self.stale_ms + 1)
        if age > self.stale_ms:
            self.stats.stale += 1
            return  # an input is too old to act on: stop commanding
        dt = (t_ms - self._last_decision_ms) / 1000.0 if self._last_decision_ms >= 0 else self.mission.dt
        obs = self._paced_observation(pose)
        cmd = self.autonomy.step(obs, dt, np.ones(1, dtype=bool))
        vx, vy, _, yaw = encode_command(cmd.heading, cmd.speed, cmd.surface)
        vz = depth_rate(pose.depth, bool(cmd.surface[0]))
        answer = {"tick_ms": t_ms, "vx": float(vx[0]), "vy": float(vy[0]), "vz": vz, "yaw": float(yaw[0])}
        self._pub.put(json.dumps(answer))
        self.stats.latency_s.append(time.perf_counter() - received)
        self.stats.input_age_ms.append(int(age))
        self.stats.ticks.append(t_ms)
        self.stats.decisions += 1
        self._last_answer, self._last_decision_ms, self._last_sent_ms = answer, t_ms, t_ms
        self.last_tick_ms = t_ms
        self.steps += 1
        self._publish_status(t_ms)

    def _paced_observation(self, pose) -> Observation:
        tel, k = self.telemetry, self.n_contacts
        cx, cy, seen = np.zeros((1, k)), np.zeros((1, k)), np.zeros((1, k), dtype=bool)
        for j, c in tel.recent_contacts(pose.time_ms - self.period_ms).items():
            if 0 <= j < k:
                cx[0, j], cy[0, j], seen[0, j] = c.east, c.north, True
        assert tel.energy_hj is not None and self.clock is not None
        battery = battery_fraction(self.start_wh, np.array([tel.energy_hj]), self.mission.vehicle.battery_wh)
        return Observation(
            (pose.time_ms - self.clock.start_ms) / 1000.0,
            np.array([pose.east]),
            np.array([pose.north]),
            np.array([pose.heading]),
            battery,
            cx,
            cy,
            np.zeros((1, k)),
            seen,
            surfaced=np.array([pose.surfaced]),
        )

    def _publish_status(self, tick_ms: int) -> None:
        a = self.autonomy
        status = {
            "tick_ms": tick_ms,
            "goal": int(a.goal_kind[0]),
            "returning": bool(a.goal_kind[0] == GOAL_RETURN),
            "return_reason": int(a.return_reason[0]),
            "wp_aborted": [bool(v) for v in a.wp_aborted[0]],
        }
        if self.pacing == "vehicle":
            status["decisions"] = self.stats.as_dict()
            status["telemetry"] = vars(self.telemetry.counts)
        self._status.put(json.dumps(status))
