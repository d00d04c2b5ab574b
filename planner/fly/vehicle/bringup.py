"""Bring a vehicle we do not simulate up to a scenario's start, the way a careful operator does.

Heartbeat (is it a submarine, is it free to take?), telemetry at the rates the back-seat
needs (SET_MESSAGE_INTERVAL, else the older REQUEST_DATA_STREAM), a position estimate
(EKF_STATUS_REPORT and, where the vehicle reports one, a GPS fix), the vehicle inside the
scenario's operational area, the scenario's mission uploaded for the record, GUIDED,
armed, down to the mission depth — then the scenario clock starts.  Every step has a
timeout and fails with one line that names it; nothing moves the vehicle before GUIDED,
and nothing at all is commanded before the checks that can refuse the run have passed.
Each step is published on ``status/bringup`` as it happens, so the log keeps the timeline.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, NoReturn

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.mission_upload import MissionItem  # noqa: E402
from bridge.setpoint import Setpoint  # noqa: E402
from bridge.vehicle_commands import ARDUSUB_MODES  # noqa: E402
from planner.common.telemetry import SURFACE_BAND_M, VehicleTelemetry  # noqa: E402
from planner.fly.vehicle.guard import GuardOptions  # noqa: E402
from planner.fly.vehicle.preflight import Preflight, result_name  # noqa: E402
from rapt.errors import InputError, LinkTimeoutError, RefusedError, RunError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.interface import DEPTH_M, depth_rate  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402

__all__ = ["BringUp", "BringUpTimeouts", "Step", "STREAMS", "mission_items"]

#: Messages the back-seat, the referee and the watchdog read, and the rate (Hz, vehicle time) asked for.
STREAMS = {
    "GLOBAL_POSITION_INT": 10.0,
    "ATTITUDE": 10.0,
    "BATTERY_STATUS": 2.0,
    "SYS_STATUS": 1.0,
    "EKF_STATUS_REPORT": 1.0,
    "GPS_RAW_INT": 1.0,
    "SYSTEM_TIME": 1.0,
}
#: Parameters asked for once, so the log says what the run checks judge against (thrusters' PWM limits).
LOGGED_PARAMETERS = ("MOT_PWM_MIN", "MOT_PWM_MAX")
#: REQUEST_DATA_STREAM groups carrying STREAMS (ArduPilot's mapping), for vehicles without SET_MESSAGE_INTERVAL.
DATA_STREAMS = {
    mavlink.MAV_DATA_STREAM_POSITION: 10,  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED
    mavlink.MAV_DATA_STREAM_EXTRA1: 10,  # ATTITUDE
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: 2,  # SYS_STATUS, GPS_RAW_INT
    mavlink.MAV_DATA_STREAM_EXTRA3: 2,  # BATTERY_STATUS, EKF_STATUS_REPORT, SYSTEM_TIME
}
#: The vehicle is at the mission depth when within this many metres of it on this many reports running.
DEPTH_TOLERANCE_M = 0.3
DEPTH_REPORTS = 3

GUIDED = ARDUSUB_MODES["GUIDED"]
SURFACE = ARDUSUB_MODES["SURFACE"]
ALT_HOLD = ARDUSUB_MODES["ALT_HOLD"]
#: The vehicle starts a scenario within this many metres of its start, unless told otherwise.
START_TOLERANCE_M = 10.0
#: A disarmed vehicle at most this far from its start is flown back to it by default (a transit leg after the
#: dive, logged, not scored): at the surface a current carries a disarmed vehicle off its start in the minute or
#: two that bring-up takes (0.3 m/s for two minutes is 36 m). Farther, it was put in the wrong place: refused.
DRIFT_TRANSIT_M = 50.0
#: A transit leg's speed through the water at most (m/s), and the slowest it is given time for.
TRANSIT_MPS, TRANSIT_SLOWEST_MPS = 1.0, 0.25
_EKF_ABS = mavlink.EKF_POS_HORIZ_ABS
_EKF_CONST = mavlink.EKF_CONST_POS_MODE


@dataclass(frozen=True)
class BringUpTimeouts:
    """Wall seconds each bring-up step may take before the run is called off."""

    heartbeat: float = 15.0
    streams: float = 10.0
    estimate: float = 180.0
    mission: float = 20.0
    guided: float = 60.0
    arm: float = 20.0
    depth: float = 120.0
    surface: float = 60.0  # after the run: for the vehicle to reach the surface before it is disarmed
    guard: float = 20.0  # the onboard guard's upload, restart and first report
    transit: float = 60.0  # beyond the time a transit leg needs at its slowest

    def scaled(self, factor: float) -> BringUpTimeouts:
        return BringUpTimeouts(**{k: v * factor for k, v in asdict(self).items()})


def mission_items(
    mission: Mission, home: tuple[float, float], route: Sequence[tuple[float, float]] = ()
) -> list[MissionItem]:
    """The scenario's route as mission items: home (seq 0, ArduPilot's), waypoints at depth, recovery on top.

    ``route`` (a calibration run's leg starts, ending at the recovery point) replaces the
    mission's waypoints and recovery: what the vehicle will fly is what its mission shows.
    """
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    route = route or (*mission.waypoints, mission.recovery)
    points = [(*frame.to_latlon(x, y), -DEPTH_M) for x, y in route[:-1]]
    points.append((*frame.to_latlon(*route[-1]), 0.0))
    items = [MissionItem.waypoint(0, home[0], home[1], 0.0, frame=mavlink.MAV_FRAME_GLOBAL)]
    return items + [MissionItem.waypoint(seq, lat, lon, z) for seq, (lat, lon, z) in enumerate(points, start=1)]


@dataclass
class Step:
    name: str
    status: str  # "ok", "failed", "fallback", "note"
    wall_s: float
    time_boot_ms: int | None
    detail: str = ""


@dataclass
class BringUp(Preflight):
    """Bring the vehicle behind ``bridge`` (:class:`bridge.mavlink_bridge.MavlinkBridge`) up for scenario ``u``.

    ``say(step)`` is told each step as it ends.  :meth:`run` returns the vehicle time
    (``time_boot_ms``) at which the scenario clock starts, published on ``meta/clock``.
    """

    bridge: MavlinkBridge
    session: Any  # zenoh.Session
    vehicle: str
    mission: Mission
    connection: str
    timeouts: BringUpTimeouts = field(default_factory=BringUpTimeouts)
    say: Callable[[Step], None] | None = None
    timeline: list[Step] = field(default_factory=list)
    route: tuple[tuple[float, float], ...] = ()  # a calibration run's leg starts (:func:`mission_items`)
    #: the onboard guard to install (:mod:`planner.fly.vehicle.guard`); None flies without one, and says so
    guard_options: GuardOptions | None = field(default_factory=GuardOptions)
    #: how far from the scenario's start the vehicle may be; farther, it is refused, or flown there with ``transit``
    start_tolerance_m: float = START_TOLERANCE_M
    transit: bool = False
    #: a disarmed vehicle this far off its start (beyond the tolerance) is flown back without ``transit``; 0: never
    drift_transit_m: float = DRIFT_TRANSIT_M

    def __post_init__(self) -> None:
        #: GUIDED was accepted: from here on the vehicle is ours to bring back (never before:
        #: a vehicle refused at the heartbeat may be armed and flown by someone else).
        self.took_control = False
        self._t0 = time.monotonic()
        self.telemetry = VehicleTelemetry(LocalFrame(self.mission.origin_lat, self.mission.origin_lon))
        self.pace = 1.0  # the vehicle's clock against the wall's, once measured (:meth:`_pace`)
        self._transit_m = 0.0  # how far :meth:`start` found the vehicle from the scenario's start
        self._status = self.session.declare_publisher(keys.status(self.vehicle, keys.BRINGUP_SOURCE))
        self._commands = self.session.declare_publisher(keys.command(self.vehicle, keys.BRINGUP_SOURCE))

    def close(self) -> None:
        for entity in (self._status, self._commands):
            try:
                entity.undeclare()
            except Exception:  # the session may already be closed
                pass

    # -- the sequence ------------------------------------------------------------------------
    def run(self) -> int:
        self.heartbeat()
        self.signing()
        self.streams()
        self.previous()
        self.estimate()
        self.inside_area()
        self.start()
        self.guard()
        self.upload()
        self.guided()
        self.arm()
        self.dive()
        self.transit_leg()
        return self.start_clock()

    def heartbeat(self) -> None:
        b = self.bridge
        hb = self._wait(lambda: b.autopilot, self.timeouts.heartbeat)
        if hb is None:
            failures = b.stats.get("open_failures", 0)
            why = f"could not open it ({failures} tries)" if failures else "no HEARTBEAT from an autopilot"
            bad = b.stats.get("bad_signature", 0)
            if bad:
                why = (
                    f"its frames are signed with another key ({bad} refused: signatures do not match); give "
                    "--signing-key the vehicle's key, or clear the key on the vehicle"
                )
            self._fail(
                "heartbeat",
                LinkTimeoutError(
                    f"--mavlink {self.connection}: {why} within {self.timeouts.heartbeat:g} s; "
                    "check the address and that the vehicle is on"
                    + (" and that no other program holds the port" if self.connection.startswith("tcp:") else "")
                ),
            )
        if hb.type != mavlink.MAV_TYPE_SUBMARINE:
            kind = mavlink.enums["MAV_TYPE"][hb.type].name if hb.type in mavlink.enums["MAV_TYPE"] else str(hb.type)
            self._fail(
                "heartbeat",
                InputError(
                    f"--mavlink {self.connection}: the vehicle is a {kind}, not a submarine (MAV_TYPE_SUBMARINE); "
                    "connect to an ArduSub vehicle"
                ),
            )
        mode = hb.mode_label
        if hb.armed and hb.custom_mode not in (GUIDED, SURFACE):  # GUIDED or SURFACE: an earlier run's (previous())
            whose = (
                "a pilot's hold, or an earlier run's vehicle that SURFACE brought to the top"
                if hb.custom_mode == ALT_HOLD
                else "someone else is flying it"
            )
            self._fail(
                "heartbeat",
                RefusedError(
                    f"--mavlink {self.connection}: the vehicle is already armed in {mode} ({whose}): "
                    "disarm it before rapt-plan run"
                ),
            )
        system = self.bridge.target[0] if self.bridge.target else "?"
        self._ok("heartbeat", f"submarine, system {system}, {mode}, " + ("armed" if hb.armed else "disarmed"))

    def streams(self) -> None:
        b = self.bridge
        asked = time.monotonic()
        refused = ""
        for name, hz in STREAMS.items():
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            try:
                result = b.set_message_interval(msg_id, hz, timeout=0.5, retries=1)
            except TimeoutError:
                refused = f"no answer to SET_MESSAGE_INTERVAL for {name}"
                break  # an older firmware: asking for the rest would only take longer
            if result != mavlink.MAV_RESULT_ACCEPTED:
                refused = f"SET_MESSAGE_INTERVAL refused for {name} ({result_name(result)})"
                break
        if refused:
            for stream, hz in DATA_STREAMS.items():
                b.request_data_stream(stream, hz)
            self.note("streams", "fallback", f"{refused}: REQUEST_DATA_STREAM for all")
        for name in LOGGED_PARAMETERS:  # answered as telemetry, into the log (planner.review.run_checks)
            b.request_parameter(name)
        needed = ("GLOBAL_POSITION_INT", "ATTITUDE", "BATTERY_STATUS")
        fresh = self._wait(lambda: all(self._since(n, asked) for n in needed) or None, self.timeouts.streams)
        if fresh is None:
            missing = [n for n in needed if not self._since(n, asked)]
            self._fail(
                "streams",
                LinkTimeoutError(
                    f"bring-up streams: no {', '.join(missing)} within {self.timeouts.streams:g} s of asking"
                ),
            )
        self._ok("streams", ", ".join(f"{n} {hz:g} Hz" for n, hz in STREAMS.items()))

    def previous(self) -> None:
        """A vehicle still armed in GUIDED or SURFACE is an earlier run's (ours, or one whose computer died and
        whose guard is surfacing it): it is surfaced and disarmed before this run starts, so nothing of that
        run's state (its depth, its place, its armed motors) passes for this scenario's start.  At the top
        ArduSub leaves SURFACE for ALT_HOLD by itself; armed in ALT_HOLD before we asked, it could as well
        be a pilot's, and :meth:`heartbeat` refuses it."""
        hb = self.bridge.autopilot
        if hb is None or not hb.armed:
            return
        label = hb.mode_label
        if hb.custom_mode == GUIDED:
            self._command_until("previous", lambda: self.bridge.set_mode("SURFACE"), self.timeouts.guided)

        def up() -> bool | None:
            self._feed()
            pose, mode = self.telemetry.pose, self._mode()
            if mode == ALT_HOLD and pose is not None and pose.depth < SURFACE_BAND_M:
                return True  # ArduSub's SURFACE hands over to ALT_HOLD once it is at the top (SURFACE_COMPLETE)
            if mode not in (GUIDED, SURFACE):
                self._fail(
                    "previous",
                    RefusedError(f"bring-up previous: while surfacing, the vehicle went to {self._mode_label()}"),
                )
            return True if pose is not None and pose.surfaced else None

        if self._wait(up, self.timeouts.surface) is None:
            pose = self.telemetry.pose
            depth = f"{pose.depth:.1f} m" if pose is not None else "unknown"
            self._fail(
                "previous",
                LinkTimeoutError(
                    f"bring-up previous: the vehicle, armed in {label} from an earlier run, did not surface within "
                    f"{self.timeouts.surface:g} s (depth {depth}); recover it by hand, then run again"
                ),
            )
        self._command_until("previous", lambda: self.bridge.arm(False), self.timeouts.arm)
        if self._wait(lambda: (not self._armed()) or None, 5.0) is None:
            self._fail(
                "previous", RunError("bring-up previous: disarming was accepted but the heartbeat does not show it")
            )
        self._ok("previous", f"armed in {label} from an earlier run: surfaced and disarmed before this one")

    def estimate(self) -> None:
        def ready():
            self._feed()
            ekf, gps = self._latest("EKF_STATUS_REPORT"), self._latest("GPS_RAW_INT")
            ok = ekf is not None and ekf.flags & _EKF_ABS and not ekf.flags & _EKF_CONST
            fix = gps is None or gps.fix_type >= 3
            return True if ok and fix and self.telemetry.pose is not None else None

        if self._wait(ready, self.timeouts.estimate) is None:
            ekf, gps = self._latest("EKF_STATUS_REPORT"), self._latest("GPS_RAW_INT")
            flags = f"0x{ekf.flags:04x}" if ekf is not None else "none"
            fix = gps.fix_type if gps is not None else "none"
            self._fail(
                "estimate",
                LinkTimeoutError(
                    f"bring-up estimate: no position estimate within {self.timeouts.estimate:g} s "
                    f"(EKF_STATUS_REPORT flags {flags}, GPS fix {fix})"
                ),
            )
        pose = self.telemetry.pose
        assert pose is not None
        self._ok("estimate", f"EKF position ok at ({pose.east:.1f}, {pose.north:.1f}) m in the mission frame")

    def inside_area(self) -> None:
        pose = self.telemetry.pose
        assert pose is not None, "estimate() found a pose"
        op = self.mission.operational_area
        x0, x1, y0, y1 = op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2
        if not (x0 <= pose.east <= x1 and y0 <= pose.north <= y1):
            self._fail(
                "area",
                InputError(
                    f"--scenario: the vehicle is at ({pose.east:.0f}, {pose.north:.0f}) m, outside mission "
                    f"'{self.mission.name}' operational area x {x0:g}..{x1:g}, y {y0:g}..{y1:g}; "
                    "move it to the launch point or fly another mission"
                ),
            )
        lx, ly = self.mission.launch
        self._ok(
            "area", f"inside the operational area, {math.hypot(pose.east - lx, pose.north - ly):.0f} m from launch"
        )

    def start(self) -> None:
        """The vehicle at the scenario's start, within :attr:`start_tolerance_m`. Farther, and the vehicle disarmed
        within :attr:`drift_transit_m` (a current moved it during bring-up), or with ``transit``: flown there by
        :meth:`transit_leg` before the clock starts. Otherwise refused with the distance.

        The vehicle is disarmed here: :meth:`previous` has surfaced and disarmed an earlier run's vehicle, and
        refused any other that is armed, before this step.
        """
        pose = self.telemetry.pose
        assert pose is not None, "estimate() found a pose"
        sx, sy = self._start_point()
        d = math.hypot(pose.east - sx, pose.north - sy)
        tol = self.start_tolerance_m
        if d <= tol:
            self._ok("start", f"{d:.1f} m from the scenario's start (tolerance {tol:g} m)")
            return
        drifted = d <= self.drift_transit_m
        if not (self.transit or drifted):
            self._fail(
                "start",
                InputError(
                    f"--start-tolerance: the vehicle is {d:.0f} m from the scenario's start ({sx:g}, {sy:g}) m, more "
                    f"than {tol:g} m and beyond the {self.drift_transit_m:g} m of drift flown back by default; put it "
                    "there, or add --transit to fly there first (logged, not scored)"
                ),
            )
        self._transit_m = d
        why = "" if self.transit else f" (within --drift-transit {self.drift_transit_m:g} m: drifted while disarmed)"
        self.note(
            "start", "note", f"{d:.0f} m from the scenario's start{why}: a transit leg after the dive (not scored)"
        )

    def _start_point(self) -> tuple[float, float]:
        return self.route[0] if self.route else self.mission.launch

    def upload(self) -> None:
        gpi = self._latest("GLOBAL_POSITION_INT")
        items = mission_items(self.mission, (gpi.lat * 1e-7, gpi.lon * 1e-7), self.route)
        try:
            result = self.bridge.upload_mission(items, timeout=min(1.5, self.timeouts.mission / 6))
        except TimeoutError as exc:
            self._fail("mission", LinkTimeoutError(f"bring-up mission: {exc}"))
        if result != mavlink.MAV_MISSION_ACCEPTED:
            name = (
                mavlink.enums["MAV_MISSION_RESULT"][result].name
                if result in mavlink.enums["MAV_MISSION_RESULT"]
                else result
            )
            self._fail("mission", RefusedError(f"bring-up mission: the vehicle refused the upload ({name})"))
        what = f"{len(self.route) - 1} leg starts" if self.route else f"{len(self.mission.waypoints)} waypoints"
        self._ok("mission", f"{len(items)} items uploaded (home, {what}, recovery)")

    def guided(self) -> None:
        self._command_until("guided", lambda: self.bridge.set_mode("GUIDED"), self.timeouts.guided)
        self.took_control = True
        if self._wait(lambda: self._mode() == GUIDED or None, 5.0) is None:
            self._fail("guided", RunError("bring-up guided: GUIDED was accepted but the heartbeat does not show it"))
        self._ok("guided", "GUIDED")

    def arm(self) -> None:
        """Arm, re-checking GUIDED before every try: a pilot, a failsafe or the firmware itself may have
        changed the mode since, and armed in a pilot mode with no pilot the vehicle is adrift."""

        def in_guided() -> int:
            if self._mode() != GUIDED:
                now = self._mode_label()
                self._fail("arm", RunError(f"bring-up arm: the vehicle left GUIDED before it was armed (now {now})"))
            return self.bridge.arm(True)

        self._command_until("arm", in_guided, self.timeouts.arm)
        if self._wait(lambda: self._armed() or None, 5.0) is None:
            self._fail("arm", RunError("bring-up arm: arming was accepted but the heartbeat does not show it"))
        self._ok("arm", "armed")

    def dive(self) -> None:
        """Down to the mission depth on set-points of our own, holding position, in GUIDED."""
        self.session.put(keys.active(self.vehicle), keys.BRINGUP_SOURCE)

        def late() -> Exception:
            pose = self.telemetry.pose
            depth = f"{pose.depth:.2f}" if pose is not None else "unknown"
            return LinkTimeoutError(
                f"bring-up depth: not at {DEPTH_M:g} m within {self.timeouts.depth:g} s (depth {depth} m)"
            )

        at_depth = 0
        for pose in self._reports("depth", time.monotonic() + self.timeouts.depth, late):
            at_depth = at_depth + 1 if abs(pose.depth - DEPTH_M) <= DEPTH_TOLERANCE_M else 0
            sp = Setpoint(0.0, 0.0, depth_rate(pose.depth, False), pose.heading, pose.time_ms)
            self._commands.put(sp.to_json())
            if at_depth >= DEPTH_REPORTS:
                break
        self._ok("depth", f"at {pose.depth:.2f} m")

    def _reports(self, step: str, deadline: float, late: Callable[[], Exception]):
        """Each new position report, while the vehicle stays in GUIDED; past ``deadline`` (monotonic) the step
        fails with ``late()``, out of GUIDED with the mode it is in now."""
        last_ms = -1
        while True:
            if time.monotonic() > deadline:
                self._fail(step, late())
            if self._mode() != GUIDED:
                self._fail(step, RunError(f"bring-up {step}: the vehicle left GUIDED (now {self._mode_label()})"))
            self._feed()
            pose = self.telemetry.pose
            if pose is None or pose.time_ms == last_ms:
                time.sleep(0.005)
                continue
            last_ms = pose.time_ms
            yield pose

    def transit_leg(self) -> None:
        """At depth, in GUIDED, on set-points of the bring-up's own: to the scenario's start (to half the
        tolerance), before the clock starts. Logged as a bring-up step; the scenario's track begins after it."""
        if not self._transit_m:
            return
        sx, sy = self._start_point()
        arrive = max(1.0, self.start_tolerance_m / 2)
        speed = min(TRANSIT_MPS, self.mission.vehicle.cruise_speed)
        budget_s = self._transit_m / TRANSIT_SLOWEST_MPS + self.timeouts.transit  # vehicle seconds
        deadline = time.monotonic() + budget_s / max(self.pace, 1e-3)

        def late() -> Exception:
            pose = self.telemetry.pose
            left = math.hypot(pose.east - sx, pose.north - sy) if pose is not None else float("nan")
            return LinkTimeoutError(f"bring-up transit: still {left:.0f} m from the start after {budget_s:.0f} s")

        first_ms = last_ms = -1
        for pose in self._reports("transit", deadline, late):
            first_ms, last_ms = (pose.time_ms if first_ms < 0 else first_ms), pose.time_ms
            de, dn = sx - pose.east, sy - pose.north
            d = math.hypot(de, dn)
            if d <= arrive:
                break
            heading = math.atan2(de, dn)  # compass: from north, clockwise
            v = min(speed, max(0.2, 0.5 * d))  # slows over the last metres
            sp = Setpoint(
                v * math.cos(heading), v * math.sin(heading), depth_rate(pose.depth, False), heading, pose.time_ms
            )
            self._commands.put(sp.to_json())
        stop = Setpoint(0.0, 0.0, depth_rate(pose.depth, False), pose.heading, pose.time_ms)
        self._commands.put(stop.to_json())
        took = (last_ms - first_ms) / 1000.0
        self._ok(
            "transit",
            f"{self._transit_m:.0f} m to the scenario's start in {took:.0f} s, now {d:.1f} m off (not scored)",
        )

    def start_clock(self) -> int:
        pose = self.telemetry.pose
        assert pose is not None
        start_ms = pose.time_ms
        self.session.put(keys.meta(self.vehicle, "clock"), json.dumps({"start_ms": start_ms}))
        self._ok("clock", f"scenario clock starts at vehicle time {start_ms / 1000:.1f} s")
        return start_ms

    # -- helpers -------------------------------------------------------------------------------
    def _latest(self, name: str):
        got = self.bridge.latest(name)
        return None if got is None else got[0]

    def _since(self, name: str, t: float) -> bool:
        got = self.bridge.latest(name)
        return got is not None and got[1] >= t

    def _feed(self) -> None:
        for name in ("ATTITUDE", "GLOBAL_POSITION_INT"):
            msg = self._latest(name)
            if msg is not None:
                self.telemetry.add(msg)

    def _mode(self) -> int:
        hb = self.bridge.autopilot
        return -1 if hb is None else int(hb.custom_mode)

    def _mode_label(self) -> str:
        hb = self.bridge.autopilot
        return "not heard" if hb is None else hb.mode_label

    def _armed(self) -> bool:
        hb = self.bridge.autopilot
        return hb is not None and hb.armed

    def _command_until(self, step: str, send: Callable[[], int], timeout: float) -> None:
        """Repeat a COMMAND_LONG until ACCEPTED: ArduSub refuses GUIDED and arming until its estimate is ready."""
        deadline, tries, last = time.monotonic() + timeout, 0, None
        while time.monotonic() < deadline:
            tries += 1
            try:
                last = send()
            except TimeoutError:
                last = None
            if last == mavlink.MAV_RESULT_ACCEPTED:
                return
            time.sleep(0.5)
        name = result_name(last)
        self._fail(step, RefusedError(f"bring-up {step}: refused {tries} times in {timeout:g} s (last: {name})"))

    def _wait(self, get: Callable[[], object], timeout: float):
        deadline = time.monotonic() + timeout
        while True:
            value = get()
            if value is not None:
                return value
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.02)

    def _record(self, name: str, status: str, detail: str) -> Step:
        self._feed()  # stamped with the vehicle's time now, also for steps noted long after bring-up
        step = Step(
            name,
            status,
            round(time.monotonic() - self._t0, 3),
            self.telemetry.now_ms if self.telemetry.now_ms >= 0 else None,
            detail,
        )
        self.timeline.append(step)
        self._status.put(json.dumps(asdict(step)))
        if self.say is not None:
            self.say(step)
        return step

    def _ok(self, name: str, detail: str) -> None:
        self._record(name, "ok", detail)

    def note(self, name: str, status: str, detail: str) -> None:
        """Add a step to the timeline (the run's recovery after the scenario, for instance)."""
        self._record(name, status, detail)

    def _fail(self, name: str, error: Exception) -> NoReturn:
        self._record(name, "failed", str(error))
        raise error
