"""A watchdog that takes the vehicle away from the back-seat when a scenario's safety rule is broken.

On the water the back-seat is software under test: it may steer into a virtual barrier,
cross a no-go area, leave the range, run the scenario's charge flat, hang, or lose the
vehicle.  The dissertation's live-virtual ranges (chapter 2) keep a watchdog beside it
that takes over; issue 22 asks for the same.  The rules are pure (:class:`WatchdogRules`:
explicit values in, the first broken rule out) and judge what the vehicle reports, with
the scorer's own tests (touching means signed distance <= 0, as in
:mod:`sim.uuv.scoring`).  :class:`Watchdog` runs them on the bus from :meth:`Watchdog.begin`
(the scenario clock) on; the first trigger is final: it makes itself the active source
(``control/active``), surfaces the vehicle (SURFACE mode plus rising set-points) or holds it
(zero-velocity set-points, refreshed because ArduSub drops a velocity target after 3 s),
and publishes the intervention on its status key for the log and the run's end condition.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
import zenoh  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.service import Service  # noqa: E402
from bridge.session import undeclare  # noqa: E402
from bridge.setpoint import Setpoint  # noqa: E402
from planner.common.telemetry import VIRTUAL_BATTERY_ID, FrameDecoder, Pose, VehicleTelemetry  # noqa: E402
from planner.fly.vehicle.virtual_range import scenario_of, sense_at  # noqa: E402
from rapt.errors import InputError, LinkError, LinkTimeoutError, RaptError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.geometry import rect_signed_distance  # noqa: E402
from sim.uuv.interface import HJ_PER_WH, SURFACE_VZ  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.scenario import Scenarios  # noqa: E402

__all__ = [
    "COLLISION",
    "NOGO",
    "OPERATIONAL_AREA",
    "BATTERY",
    "POSITION_LOST",
    "STALE_COMMANDS",
    "LINK_LOST",
    "REASONS",
    "ACTIONS",
    "Trigger",
    "WatchdogRules",
    "contact_distances",
    "Commander",
    "Watchdog",
]

#: Reasons, in the order the rules are checked.
COLLISION = "collision"
NOGO = "nogo"
OPERATIONAL_AREA = "operational_area"
BATTERY = "battery"
POSITION_LOST = "position_lost"
STALE_COMMANDS = "stale_commands"
LINK_LOST = "link_lost"
REASONS = (COLLISION, NOGO, OPERATIONAL_AREA, BATTERY, POSITION_LOST, STALE_COMMANDS, LINK_LOST)
#: EKF_STATUS_REPORT flags: an absolute horizontal position, and the constant-position fallback.
_EKF_POS_HORIZ_ABS = 16
_EKF_CONST_POS_MODE = 128
#: What the watchdog does when it takes over.
ACTIONS = ("surface", "hold")


@dataclass(frozen=True)
class Trigger:
    """A broken rule: one of :data:`REASONS` and a one-line detail."""

    reason: str
    detail: str


def contact_distances(scen: Scenarios, pose: Pose) -> np.ndarray:
    """(K,) signed distances from ``pose`` to scenario row 0's obstacles then barriers (negative inside)."""
    return sense_at(scen, pose).distance[0]


def _positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise InputError(f"{name}: expected a number > 0, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class WatchdogRules:
    """The thresholds; :meth:`check` applies them to explicit values (no clock, no bus).

    ``critical_battery`` is a fraction of the mission's battery capacity on the scenario's
    virtual gauge (0: empty, the scenario's own end — the pack behind it is real and fine),
    ``pack_critical_percent`` the vehicle's real pack (its BATTERY_STATUS id 0
    ``battery_remaining``), ``command_stale_s`` vehicle seconds without a set-point from the
    watched back-seat, ``link_lost_s`` wall seconds without a frame from the vehicle,
    ``position_stale_s`` vehicle seconds without a position report while other reports come
    (the estimator lost, or stopped reporting: the back-seat is flying blind).
    ``record_only`` names reasons that are published as a violation but do not take control
    (a virtual no-go area the plan predicts the vehicle to enter, for instance).
    """

    critical_battery: float = 0.0
    command_stale_s: float = 6.0
    link_lost_s: float = 3.0
    pack_critical_percent: float = 10.0
    position_stale_s: float = 3.0
    record_only: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        b = self.critical_battery
        if isinstance(b, bool) or not isinstance(b, (int, float)) or not 0 <= b < 1:
            raise InputError(f"critical_battery: expected a fraction in [0, 1), got {b!r}")
        _positive(self.command_stale_s, "command_stale_s")
        _positive(self.link_lost_s, "link_lost_s")
        _positive(self.position_stale_s, "position_stale_s")
        p = self.pack_critical_percent
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0 <= p < 100:
            raise InputError(f"pack_critical_percent: expected a percentage in [0, 100), got {p!r}")
        unknown = set(self.record_only) - set(REASONS)
        if unknown:
            raise InputError(f"record_only: unknown reason(s) {sorted(unknown)}; known: {', '.join(REASONS)}")
        object.__setattr__(self, "record_only", frozenset(self.record_only))

    def check(self, *args: Any, **kwargs: Any) -> Trigger | None:
        """The first rule of :data:`REASONS` that the values break, or None (arguments as :meth:`broken`)."""
        broken = self.broken(*args, **kwargs)
        return broken[0] if broken else None

    def broken(
        self,
        scen: Scenarios,
        pose: Pose | None,
        contact_distance: np.ndarray | None,
        battery: float | None,
        command_age_s: float | None,
        link_silence_s: float | None,
        pack_percent: float | None = None,
        *,
        position_age_s: float | None = None,
        ekf_flags: int | None = None,
    ) -> list[Trigger]:
        """Every rule the values break, in the order of :data:`REASONS`.

        ``pose`` (None: no position yet, the area rules wait), ``contact_distance`` (K,) as
        :func:`contact_distances` gives, ``battery`` the charge fraction (None: unknown),
        ``command_age_s`` vehicle seconds since the last set-point (None: unknown),
        ``link_silence_s`` wall seconds since the vehicle's last frame and ``pack_percent`` the
        real pack's charge (None: unknown); ``position_age_s`` vehicle seconds since the last
        position report and ``ekf_flags`` the last EKF_STATUS_REPORT's flags (None: unknown).
        """
        values = (scen, pose, contact_distance, battery, command_age_s, link_silence_s, pack_percent)
        return [t for t in self._each(*values, position_age_s, ekf_flags) if t]

    def _each(
        self,
        scen,
        pose,
        contact_distance,
        battery,
        command_age_s,
        link_silence_s,
        pack_percent,
        position_age_s,
        ekf_flags,
    ):
        m = scen.mission
        if pose is not None:
            x, y = np.array([pose.east]), np.array([pose.north])
            if contact_distance is not None and contact_distance.size:
                j = int(np.argmin(contact_distance))
                if contact_distance[j] <= 0:
                    n_obstacles = len(m.obstacles)
                    what = (
                        f"obstacle {m.obstacles[j].name}"
                        if j < n_obstacles
                        else f"barrier {m.barriers[j - n_obstacles].name}"
                    )
                    yield Trigger(COLLISION, f"touched {what} (signed distance {contact_distance[j]:.1f} m)")
            if scen.nogo.shape[1]:
                d = rect_signed_distance(x, y, scen.nogo[:1])[0]
                k = int(np.argmin(d))
                if d[k] <= 0:
                    yield Trigger(NOGO, f"inside no-go area {m.nogo[k].name} ({-d[k]:.1f} m from its edge)")
            op = m.operational_area
            xmin, xmax, ymin, ymax = (
                op.x - op.width / 2,
                op.x + op.width / 2,
                op.y - op.height / 2,
                op.y + op.height / 2,
            )
            margin = min(pose.east - xmin, xmax - pose.east, pose.north - ymin, ymax - pose.north)
            if margin < 0:
                yield Trigger(
                    OPERATIONAL_AREA,
                    f"{-margin:.1f} m outside the operational area at ({pose.east:.1f}, {pose.north:.1f})",
                )
        if battery is not None and battery <= self.critical_battery:
            yield Trigger(
                BATTERY, f"scenario battery at {100 * battery:.1f}% (critical: {100 * self.critical_battery:.1f}%)"
            )
        if pack_percent is not None and 0 <= pack_percent <= self.pack_critical_percent:
            yield Trigger(
                BATTERY, f"the vehicle's pack at {pack_percent:g}% (critical: {self.pack_critical_percent:g}%)"
            )
        if ekf_flags is not None and (not ekf_flags & _EKF_POS_HORIZ_ABS or ekf_flags & _EKF_CONST_POS_MODE):
            yield Trigger(
                POSITION_LOST, f"the vehicle's estimator has no absolute position (EKF flags 0x{ekf_flags:04x})"
            )
        elif position_age_s is not None and position_age_s > self.position_stale_s:
            yield Trigger(
                POSITION_LOST,
                f"no position report for {position_age_s:.1f} s of vehicle time (limit {self.position_stale_s:g} s)",
            )
        if command_age_s is not None and command_age_s > self.command_stale_s:
            yield Trigger(
                STALE_COMMANDS,
                f"no set-point for {command_age_s:.1f} s of vehicle time (limit {self.command_stale_s:g} s)",
            )
        if link_silence_s is not None and link_silence_s > self.link_lost_s:
            yield Trigger(
                LINK_LOST, f"no frame from the vehicle for {link_silence_s:.1f} s (limit {self.link_lost_s:g} s)"
            )
        return None


class Commander(Protocol):
    """What the watchdog needs of the link (the :class:`bridge.mavlink_bridge.MavlinkBridge` is one)."""

    def set_mode(self, mode: str) -> int: ...

    @property
    def linked(self) -> bool: ...


class Watchdog(Service):
    """Watch scenario ``u`` of ``mission`` flown by back-seat source ``watched``; take over on the first broken rule.

    Nothing is judged before :meth:`begin`. On a trigger :attr:`intervention` becomes its
    reason, ``control/active`` becomes :data:`bridge.keys.WATCHDOG_SOURCE`, set-points go out as that source at
    ``setpoint_hz`` until :meth:`close` (rising for ``"surface"``, zero velocity for
    ``"hold"``), and for ``"surface"`` ``commander.set_mode("SURFACE")`` is sent from the
    watchdog's own thread, retried while the link is down. The intervention is published
    on ``status/watchdog`` as JSON ``{"event": "intervention", "reason", "detail",
    "time_boot_ms", "action", "mode_result"}`` (``mode_result`` null unless a COMMAND_ACK
    came back on the first try; a later success follows as ``{"event": "mode", ...}``).
    """

    _what = "watchdog"

    def __init__(
        self,
        session: zenoh.Session,
        vehicle: str,
        mission: Mission,
        u,
        commander: Commander | None,
        *,
        action: str = "surface",
        watched: str = keys.DEFAULT_ACTIVE,
        rules: WatchdogRules | None = None,
        setpoint_hz: float = 2.0,
        mode_retry_s: float = 0.5,
    ):
        super().__init__()
        if action not in ACTIONS:
            raise InputError(f"action: expected one of {', '.join(ACTIONS)}, got {action!r}")
        if action == "surface" and commander is None:
            raise InputError("commander: the 'surface' action needs a commander with set_mode (the bridge)")
        keys.command(vehicle, watched)  # validates both names
        if watched == keys.WATCHDOG_SOURCE:
            raise InputError(f"watched: {keys.WATCHDOG_SOURCE!r} is the watchdog's own source")
        self.mission, self.vehicle, self.watched, self.action = mission, vehicle, watched, action
        #: Rules broken that were only recorded (``rules.record_only``): reason -> detail.
        self.violations: dict[str, str] = {}
        self.commander = commander
        self.rules = rules if rules is not None else WatchdogRules()
        self.setpoint_period_s = 1.0 / _positive(setpoint_hz, "setpoint_hz")
        self.mode_retry_s = _positive(mode_retry_s, "mode_retry_s")
        self.scen = scenario_of(mission, u)
        self.start_wh = float(self.scen.battery0[0]) * float(mission.vehicle.battery_wh)
        self.telemetry = VehicleTelemetry(LocalFrame(mission.origin_lat, mission.origin_lon), VIRTUAL_BATTERY_ID)
        self._decoder = FrameDecoder()
        self._begin = threading.Event()
        self._armed = False
        self._armed_at = math.inf  # monotonic
        self._since_ms: int | None = None  # vehicle time when armed: commands are due from then on
        self._last_command_ms = -1  # vehicle time when the watched source's last set-point arrived
        self._last_frame = -math.inf  # monotonic time of the vehicle's last frame (virtual ones do not count)
        self._distances: np.ndarray | None = None
        self._trigger: Trigger | None = None
        self._setpoint: Setpoint | None = None
        self._next_setpoint = 0.0
        #: The published intervention event (None until a trigger).
        self.event: dict[str, Any] | None = None
        self._counts = dict.fromkeys(
            ("frames_in", "virtual_in", "poses", "commands_in", "commands_invalid", "setpoints_out", "mode_attempts"), 0
        )
        self._session = session
        self._raw = session.declare_subscriber(keys.raw(vehicle))  # FIFO channels, read by our thread
        self._commands = session.declare_subscriber(keys.command(vehicle, watched))
        self._out = session.declare_publisher(keys.command(vehicle, keys.WATCHDOG_SOURCE))
        self._status = session.declare_publisher(
            keys.status(vehicle, keys.WATCHDOG_SOURCE), encoding=zenoh.Encoding.APPLICATION_JSON
        )
        self._token = session.liveliness().declare_token(keys.alive(vehicle, keys.WATCHDOG_SOURCE))

    # -- life cycle ------------------------------------------------------------------
    def _open(self) -> None:
        self._spawn(f"watchdog-{self.vehicle}", self._run)

    def _shutdown(self) -> None:
        self._join(self._threads, timeout=10)
        undeclare(self._raw, self._commands, self._out, self._status, self._token)

    def begin(self) -> None:
        """The scenario clock starts: judge from now on."""
        self._begin.set()

    @property
    def armed(self) -> bool:
        """:meth:`begin` was called and the watchdog's thread has taken it up."""
        return self._armed

    @property
    def intervention(self) -> str | None:
        """The reason the watchdog took over (one of :data:`REASONS`), or None."""
        t = self._trigger
        return None if t is None else t.reason

    @property
    def trigger(self) -> Trigger | None:
        return self._trigger

    @property
    def stats(self) -> dict[str, int]:
        """Counters: frames (and virtual ones) read, poses, the watched source's set-points, set-points and mode commands sent."""
        return dict(self._counts)

    # -- the loop --------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            busy = self._drain_raw() | self._drain_commands()
            if not self._armed and self._begin.is_set():
                self._arm()
            if self._armed and self._trigger is None:
                broken = self.rules.broken(
                    self.scen,
                    self.telemetry.pose,
                    self._distances,
                    self._battery(),
                    self._command_age_s(),
                    self._silence_s(),
                    self._pack_percent(),
                    position_age_s=self._position_age_s(),
                    ekf_flags=None if self.telemetry.ekf is None else int(self.telemetry.ekf.flags),
                )
                for trigger in broken:
                    if trigger.reason not in self.rules.record_only:
                        self._take_over(trigger)
                        break
                    self._record(trigger)
            if self._setpoint is not None and time.monotonic() >= self._next_setpoint:
                self._send_setpoint()
            if not busy:
                time.sleep(0.005)

    def _drain_raw(self) -> bool:
        got = False
        while (sample := self._raw.try_recv()) is not None:
            got = True
            attachment = sample.attachment
            if attachment is not None and attachment.to_bytes() == keys.VIRTUAL_ATTACHMENT:
                self._counts["virtual_in"] += 1
            else:
                self._last_frame = time.monotonic()
            for msg in self._decoder.decode(sample.payload.to_bytes()):
                if msg.get_type() == "BAD_DATA":
                    continue
                self._counts["frames_in"] += 1
                if self.telemetry.add(msg) == "position":
                    self._counts["poses"] += 1
                    assert self.telemetry.pose is not None, "a position report just set the pose"
                    self._distances = contact_distances(self.scen, self.telemetry.pose)
        return got

    def _drain_commands(self) -> bool:
        got = False
        while (sample := self._commands.try_recv()) is not None:
            got = True
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            try:
                Setpoint.from_json(sample.payload.to_bytes())
            except ValueError:
                self._counts["commands_invalid"] += 1
                continue
            self._counts["commands_in"] += 1
            self._last_command_ms = self.telemetry.now_ms
        return got

    def _arm(self) -> None:
        self._armed, self._armed_at = True, time.monotonic()
        self._since_ms = self.telemetry.now_ms if self.telemetry.now_ms >= 0 else None

    def _position_age_s(self) -> float | None:
        pose, now = self.telemetry.pose, self.telemetry.now_ms
        return None if pose is None or now < 0 else (now - pose.time_ms) / 1000.0

    def _pack_percent(self) -> float | None:
        pack = self.telemetry.pack
        return None if pack is None or pack.battery_remaining < 0 else float(pack.battery_remaining)

    def _record(self, trigger: Trigger) -> None:
        """A rule broken that the range lets the run go on through: published once per reason."""
        if trigger.reason in self.violations:
            return
        self.violations[trigger.reason] = trigger.detail
        now = self.telemetry.now_ms
        self._publish(
            {
                "event": "violation",
                "reason": trigger.reason,
                "detail": trigger.detail,
                "time_boot_ms": now if now >= 0 else None,
            }
        )

    def _battery(self) -> float | None:
        hj = self.telemetry.energy_hj
        return None if hj is None else (self.start_wh - hj / HJ_PER_WH) / float(self.mission.vehicle.battery_wh)

    def _command_age_s(self) -> float | None:
        now = self.telemetry.now_ms
        if now < 0:
            return None
        if self._since_ms is None:  # armed before the vehicle's first timestamp: due from that one on
            self._since_ms = now
        return (now - max(self._since_ms, self._last_command_ms)) / 1000.0

    def _silence_s(self) -> float:
        return time.monotonic() - max(self._last_frame, self._armed_at)

    # -- taking over -----------------------------------------------------------------
    def _take_over(self, trigger: Trigger) -> None:
        self._trigger = trigger
        pose, now = self.telemetry.pose, self.telemetry.now_ms
        heading = 0.0 if pose is None else pose.heading
        vz = SURFACE_VZ if self.action == "surface" else 0.0
        self._setpoint = Setpoint(0.0, 0.0, vz, heading, now if now >= 0 else None)
        self._session.put(keys.active(self.vehicle), keys.WATCHDOG_SOURCE)
        self._send_setpoint()
        self.event = {
            "event": "intervention",
            "reason": trigger.reason,
            "detail": trigger.detail,
            "time_boot_ms": now if now >= 0 else None,
            "action": self.action,
            "mode_result": None,
        }
        if self.action == "surface":
            self._spawn(f"watchdog-{self.vehicle}-surface", self._surface)
        else:
            self._publish(self.event)

    def _send_setpoint(self) -> None:
        assert self._setpoint is not None, "set-points go out only after a trigger"
        self._out.put(self._setpoint.to_json())
        self._counts["setpoints_out"] += 1
        self._next_setpoint = time.monotonic() + self.setpoint_period_s

    def _surface(self) -> None:
        """SURFACE until the vehicle answers; the event goes out after the first try, a late answer after it."""
        assert self.commander is not None and self.event is not None, "checked in __init__, set before the spawn"
        attempts = 0
        while not self._stop.is_set():
            attempts += 1
            self._counts["mode_attempts"] += 1
            result: int | None = None
            error: str | None = None
            try:
                result = int(self.commander.set_mode("SURFACE"))
                final = True
            except (LinkError, LinkTimeoutError) as exc:  # the link is down: try again
                error, final = str(exc), False
            except RaptError as exc:  # refused for good (commands not allowed): say so, stop trying
                error, final = str(exc), True
            outcome = {"mode_result": result} if error is None else {"mode_result": None, "mode_error": error}
            if attempts == 1:
                self.event = {**self.event, **outcome}
                self._publish(self.event)
            elif final:
                self._publish({"event": "mode", "mode": "SURFACE", "attempts": attempts, **outcome})
            if final:
                return
            self._stop.wait(self.mode_retry_s)

    def _publish(self, event: dict[str, Any]) -> None:
        try:
            self._status.put(json.dumps(event))
        except zenoh.ZError:  # the session closed under us
            pass
