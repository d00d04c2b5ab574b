"""The back-seat autonomy as a process on the bus: telemetry in, set-points out.

It runs the very autonomy of the batch simulator (:class:`sim.uuv.autonomy.Autonomy`, one
vehicle) on what the front-seat reports over MAVLink, relayed by the bridge on Zenoh:
it reads the ordered raw frame stream, gathers one step's telemetry until SYSTEM_TIME
closes it, decides once per step (a repeated step gets the same answer again), and
publishes the set-point under its source name.  Whether that set-point reaches the
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
from bridge.session import undeclare  # noqa: E402
from rapt.errors import InputError  # noqa: E402
from sim.uuv.autonomy import GOAL_RETURN, Autonomy, Observation  # noqa: E402
from sim.uuv.interface import battery_fraction, encode_command  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402

__all__ = ["BackSeat"]


class BackSeat(Service):
    """Fly scenario ``u`` of ``mission`` from the bus of ``session`` as ``source``.

    The bus entities are declared at construction; :meth:`start` starts the loop's thread and
    :meth:`close` stops it and undeclares them (the session is left open).
    """

    _what = "back-seat"

    def __init__(self, session, vehicle: str, mission: Mission, u, source: str = "autonomy", surrogate=None):
        super().__init__()
        scen = make_scenarios(mission, np.asarray(u, dtype=float).reshape(1, -1))
        if not scen.valid[0]:
            raise InputError(f"scenario: invalid for mission '{mission.name}' ({scen.invalid_reason[0]})")
        self.mission, self.scen, self.vehicle, self.source = mission, scen, vehicle, source
        if surrogate is not None:
            surrogate.check(mission)
            self.autonomy = surrogate.autonomy(scen)
            self.beams = surrogate.spec.beams
        else:
            self.autonomy = Autonomy(scen)
            self.beams = 0
        self.start_wh = scen.battery0 * mission.vehicle.battery_wh
        self.n_contacts = scen.obstacles.shape[1] + scen.barriers.shape[1]
        self.session = session
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._tick: dict = {}
        self._answered: dict[int, dict] = {}
        self.last_tick_ms = -1
        self.steps = 0
        self._sub = session.declare_subscriber(keys.raw(vehicle))  # FIFO channel, read by our thread
        self._pub = session.declare_publisher(keys.command(vehicle, source))
        self._status = session.declare_publisher(keys.status(vehicle, source))
        self._token = session.liveliness().declare_token(keys.alive(vehicle, source))

    def _open(self) -> None:
        self._spawn(f"backseat-{self.source}", self._run)

    def _shutdown(self) -> None:
        self._join(self._threads, timeout=5)
        undeclare(self._sub, self._pub, self._status, self._token)  # already gone with the session: skipped

    # -- the loop --------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            sample = self._sub.try_recv()
            if sample is None:
                time.sleep(0.0002)
                continue
            for msg in self._parser.parse_buffer(sample.payload.to_bytes()) or []:
                self._on_message(msg)

    def _on_message(self, msg) -> None:
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
        a = self.autonomy
        self._status.put(
            json.dumps(
                {
                    "tick_ms": tick_ms,
                    "goal": int(a.goal_kind[0]),
                    "returning": bool(a.goal_kind[0] == GOAL_RETURN),
                    "return_reason": int(a.return_reason[0]),
                    "wp_aborted": [bool(v) for v in a.wp_aborted[0]],
                }
            )
        )

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
