"""Live-virtual mission elements: the scenario's barriers, obstacles and starting charge on a real vehicle.

On a range nobody moors a barrier for each scenario, and nobody drains a pack to the
scenario's starting charge.  As the live-virtual ranges of the dissertation's chapter 2
(TACE) do, :class:`VirtualRange` puts them on the bus instead: from the pose the vehicle
reports it computes the sonar returns exactly as :func:`sim.uuv.sonar.sense` does for the
simulator (same range, field of view and closest points), and from the pack's own
BATTERY_STATUS it keeps a fuel gauge that counts the vehicle's real consumption from the
scenario's charge.  Both go out as MAVLink frames from the vehicle's system id on the raw
stream, so a back-seat reads them as it would read a real sonar and a real gauge; each is
also published as JSON under :func:`bridge.keys.virtual` (and its raw frame carries the
attachment :data:`bridge.keys.VIRTUAL_ATTACHMENT`), so the log tells them from real ones.
"""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
import zenoh  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.frames import message_json  # noqa: E402
from bridge.service import Service  # noqa: E402
from bridge.session import receive, undeclare  # noqa: E402
from planner.common.telemetry import VIRTUAL_BATTERY_ID, FrameDecoder, Pose, VehicleTelemetry  # noqa: E402
from rapt.errors import InputError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.interface import HJ_PER_WH  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.scenario import Scenarios, make_scenarios  # noqa: E402
from sim.uuv.sonar import Contacts, sense  # noqa: E402

__all__ = ["VirtualRange", "SENSOR_COMPONENT", "body_frd", "scenario_of", "sense_at"]

#: The component id the virtual sonar and gauge send from (MAV_COMP_ID_OBSTACLE_AVOIDANCE).
SENSOR_COMPONENT = mavlink.MAV_COMP_ID_OBSTACLE_AVOIDANCE
_NO_VOLTAGE = (0, 65535)


def scenario_of(mission: Mission, u) -> Scenarios:
    """Scenario ``u`` of ``mission`` (one row); InputError when the range could not run it."""
    scen = make_scenarios(mission, np.asarray(u, dtype=float).reshape(1, -1))
    if not scen.valid[0]:
        raise InputError(f"scenario: invalid for mission '{mission.name}' ({scen.invalid_reason[0]})")
    return scen


def sense_at(scen: Scenarios, pose: Pose) -> Contacts:
    """The sonar's view (:func:`sim.uuv.sonar.sense`) of scenario row 0's obstacles and barriers from ``pose``."""
    return sense(
        np.array([pose.east]),
        np.array([pose.north]),
        np.array([pose.heading]),
        scen.obstacle_edges,
        scen.barriers,
        scen.mission.vehicle,
    )


def body_frd(pose: Pose, east: float, north: float) -> tuple[float, float]:
    """A mission-frame point as (x forward, y right) metres from ``pose`` (MAV_FRAME_BODY_FRD, level)."""
    de, dn = east - pose.east, north - pose.north
    s, c = math.sin(pose.heading), math.cos(pose.heading)
    return de * s + dn * c, de * c - dn * s


class VirtualRange(Service):
    """Virtual sonar contacts and fuel gauge of scenario ``u`` for ``vehicle`` (see the module docstring).

    Contacts follow every reported pose from :meth:`start` on; the gauge starts counting at
    :meth:`begin` (when the scenario clock starts) and publishes one virtual BATTERY_STATUS
    (id :data:`~planner.common.telemetry.VIRTUAL_BATTERY_ID`) for each pack report (id 0) after it.
    Bus entities are declared at construction and undeclared by :meth:`close`; the session is
    left open.
    """

    _what = "virtual range"

    def __init__(self, session, vehicle: str, mission: Mission, u, *, component: int = SENSOR_COMPONENT):
        super().__init__()
        if not (isinstance(component, int) and 1 <= component <= 255):
            raise InputError(f"component: expected a MAVLink component id in 1..255, got {component!r}")
        self.mission, self.vehicle, self.component = mission, vehicle, component
        self.scen = scenario_of(mission, u)
        spec = mission.vehicle
        self.capacity_wh = float(spec.battery_wh)
        self.start_wh = float(self.scen.battery0[0]) * self.capacity_wh
        self.telemetry = VehicleTelemetry(LocalFrame(mission.origin_lat, mission.origin_lon))
        self._decoder = FrameDecoder()
        self._encoders: dict[int, mavlink.MAVLink] = {}  # by the vehicle's system id: own sequence numbers
        self._lock = threading.Lock()
        self._begun = False
        self._prev: tuple[int, int, int] | None = None  # the pack's last (energy hJ, charge mAh, voltage mV)
        self._used_hj = 0.0  # drawn from the pack since begin()
        self._used_mah: float | None = None  # None while the pack reports no charge
        self._counts = dict.fromkeys(
            (
                "frames_in",
                "virtual_skipped",
                "poses",
                "contacts_sent",
                "pack_reports",
                "pack_resets",
                "pack_unreadable",
                "gauge_sent",
                "publish_errors",
            ),
            0,
        )
        self._sub = session.declare_subscriber(keys.raw(vehicle))  # FIFO channel, read by our thread
        self._raw = session.declare_publisher(
            keys.raw(vehicle), encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM, reliability=zenoh.Reliability.RELIABLE
        )
        self._json = {
            name: session.declare_publisher(keys.virtual(vehicle, name), encoding=zenoh.Encoding.APPLICATION_JSON)
            for name in ("OBSTACLE_DISTANCE_3D", "BATTERY_STATUS")
        }
        self._token = session.liveliness().declare_token(keys.alive(vehicle, "virtual-range"))

    # -- life cycle ------------------------------------------------------------------
    def _open(self) -> None:
        self._spawn(f"virtual-range-{self.vehicle}", self._run)

    def _shutdown(self) -> None:
        undeclare(self._sub)  # ends the reader's receive()
        self._join(self._threads, timeout=5)
        undeclare(self._raw, *self._json.values(), self._token)

    def begin(self) -> None:
        """The scenario clock starts: the gauge counts the pack's consumption from its last report on."""
        with self._lock:
            if not self._begun:
                self._begun, self._used_hj, self._used_mah = True, 0.0, None

    @property
    def begun(self) -> bool:
        return self._begun

    @property
    def stats(self) -> dict[str, int]:
        """Counters: frames read, own frames skipped, poses, contacts and gauge reports sent, pack readings."""
        return dict(self._counts)

    @property
    def used_wh(self) -> float:
        """Energy drawn from the pack since :meth:`begin` (Wh)."""
        return self._used_hj / HJ_PER_WH

    # -- the loop --------------------------------------------------------------------
    def _run(self) -> None:
        for sample in receive(self._sub):
            attachment = sample.attachment
            if attachment is not None and attachment.to_bytes() == keys.VIRTUAL_ATTACHMENT:
                self._counts["virtual_skipped"] += 1  # ours (or another virtual source's): not the vehicle
                continue
            for msg in self._decoder.decode(sample.payload.to_bytes()):
                self._on_message(msg)

    def _on_message(self, msg) -> None:
        self._counts["frames_in"] += 1
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        if self.telemetry.add(msg) == "position":
            self._contacts(msg.get_srcSystem())
            self._counts["poses"] += 1  # after its contacts went out
        elif kind == "BATTERY_STATUS" and int(msg.id) == 0:
            self._gauge(msg)

    def _contacts(self, sysid: int) -> None:
        pose = self.telemetry.pose
        assert pose is not None, "a position report just set the pose"
        spec = self.mission.vehicle
        c = sense_at(self.scen, pose)
        for j in np.flatnonzero(c.detected[0]):
            x, y = body_frd(pose, float(c.x[0, j]), float(c.y[0, j]))
            msg = mavlink.MAVLink_obstacle_distance_3d_message(
                pose.time_ms,
                mavlink.MAV_DISTANCE_SENSOR_ULTRASOUND,
                mavlink.MAV_FRAME_BODY_FRD,
                int(j),
                x,
                y,
                0.0,
                0.0,
                float(spec.sonar_range_m),
            )
            if self._send(sysid, msg):
                self._counts["contacts_sent"] += 1

    def _gauge(self, msg) -> None:
        self._counts["pack_reports"] += 1
        reading = (int(msg.energy_consumed), int(msg.current_consumed), int(msg.voltages[0]))
        with self._lock:
            prev, self._prev = self._prev, reading
            if not self._begun:
                return
            if prev is not None:
                self._count_draw(prev, reading)
            if reading[1] >= 0 and self._used_mah is None:
                self._used_mah = 0.0
            used_hj, used_mah = self._used_hj, self._used_mah
        left_wh = self.start_wh - used_hj / HJ_PER_WH
        remaining = int(min(100, max(0, round(100.0 * left_wh / self.capacity_wh))))
        virtual = mavlink.MAVLink_battery_status_message(
            VIRTUAL_BATTERY_ID,
            int(msg.battery_function),
            int(msg.type),
            int(msg.temperature),
            list(msg.voltages),
            int(msg.current_battery),
            -1 if used_mah is None else int(math.floor(used_mah + 1e-9)),
            int(math.floor(used_hj + 1e-9)),
            remaining,
            0,  # time_remaining: not estimated
            mavlink.MAV_BATTERY_CHARGE_STATE_UNDEFINED,
            list(msg.voltages_ext or (0, 0, 0, 0)),
            int(msg.mode or 0),
            int(msg.fault_bitmask or 0),
        )
        if self._send(msg.get_srcSystem(), virtual):
            self._counts["gauge_sent"] += 1

    def _count_draw(self, prev: tuple[int, int, int], now: tuple[int, int, int]) -> None:
        """Add what the pack reports drawn between two readings (energy, charge, voltage); under the lock."""
        (e0, q0, _), (e1, q1, mv) = prev, now
        if e0 >= 0 and e1 >= 0:
            step_hj = float(e1 - e0)
        elif q0 >= 0 and q1 >= 0 and mv not in _NO_VOLTAGE:  # no energy counter: charge times voltage
            step_hj = (q1 - q0) * mv / 1e6 * HJ_PER_WH
        else:
            self._counts["pack_unreadable"] += 1
            return
        if step_hj < 0:  # the pack's counter restarted (a reboot): count on from its new value
            self._counts["pack_resets"] += 1
            return
        self._used_hj += step_hj
        if q0 >= 0 and q1 >= 0:
            self._used_mah = (self._used_mah or 0.0) + max(0, q1 - q0)

    # -- out -------------------------------------------------------------------------
    def _send(self, sysid: int, msg) -> bool:
        """Encode ``msg`` as the vehicle's sensor (own sequence) and publish it raw and as JSON."""
        mav = self._encoders.get(sysid)
        if mav is None:
            mav = self._encoders[sysid] = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=self.component)
        frame = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        try:
            self._raw.put(frame, attachment=keys.VIRTUAL_ATTACHMENT)
            self._json[msg.get_type()].put(message_json(msg, time.time_ns()))
        except zenoh.ZError:  # the session closed under us
            self._counts["publish_errors"] += 1
            return False
        return True
