"""One scenario of a field plan flown on a vehicle we do not simulate, through its MAVLink port.

This is where the whole stack meets a real vehicle (or the simulated one as a bare
autopilot): the bridge on the vehicle's port, the vehicle-paced back-seat, the virtual
range elements (sonar returns of the scenario's barriers and obstacles, the fuel gauge
counted from the scenario's charge), the watchdog, the referee and the MCAP logger, all on
one Zenoh bus.  The bring-up (:mod:`planner.fly.vehicle.bringup`) takes the vehicle to the scenario's
start; the run ends when the referee says so (recovered, collision, out of the area,
battery empty, time limit) or the watchdog takes over, and the vehicle is then surfaced
and disarmed — as it is on Ctrl-C.  Nothing here knows whether the far end is ArduSub on
the water, ArduSub SITL or our bare-autopilot front-seat.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bridge import keys
from bridge.mavlink_bridge import MavlinkBridge
from bridge.vehicle_commands import Autopilot
from planner.common.scenario_record import SCENARIO_META, scenario_json
from planner.fly.backseat import BackSeat
from planner.fly.live import start_live_view
from planner.fly.run_bus import PART_ROLES, RunBus
from planner.fly.scenario_map import ScenarioMap
from planner.fly.vehicle.bringup import DRIFT_TRANSIT_M, GUIDED, START_TOLERANCE_M, BringUp, BringUpTimeouts, Step
from planner.fly.vehicle.guard import DEFAULT_GUARD, GuardOptions
from planner.fly.vehicle.referee import Referee
from planner.fly.vehicle.virtual_range import VirtualRange
from planner.fly.vehicle.watchdog import BATTERY, COLLISION, OPERATIONAL_AREA, REASONS, Watchdog, WatchdogRules
from rapt.errors import InputError
from sim.uuv.scenario import make_scenarios

__all__ = ["VehicleRunResult", "run_vehicle", "WATCHDOG_ACTIONS"]

#: What the watchdog does when it takes over.
WATCHDOG_ACTIONS = ("surface", "hold")


@dataclass
class VehicleRunResult:
    scores: np.ndarray
    track: np.ndarray  # (n, 8) rows of planner.common.telemetry.TrackSampler
    ended: str  # the referee's reason, "watchdog: <reason>", or "stopped by the operator"
    watchdog: str  # the watchdog's reason, "" if it never intervened
    sim_s: float  # scenario seconds flown
    wall_s: float
    start_ms: int  # the vehicle's time_boot_ms at the scenario clock's start
    decisions: dict = field(default_factory=dict)
    telemetry: dict = field(default_factory=dict)
    timeline: list[Step] = field(default_factory=list)
    bridge_stats: dict = field(default_factory=dict)
    log_path: Path | None = None
    decision_ticks: list[int] = field(default_factory=list)  # time_boot_ms each decision was taken on
    input_age_ms: list[int] = field(default_factory=list)  # the oldest input of each decision
    violations: dict = field(default_factory=dict)  # record-only watchdog reasons broken: reason -> detail
    virtual: dict = field(default_factory=dict)  # the virtual range's counters (contacts_sent, gauge_sent, ...)


def run_vehicle(
    flight,
    connection: str,
    *,
    vehicle: str = keys.DEFAULT_VEHICLE,
    log_path: str | Path | None = None,
    action: str = "surface",
    record_only: Iterable[str] = (),
    timeouts: BringUpTimeouts | None = None,
    timeout_s: float | None = None,
    say: Callable[[Step], None] | None = None,
    bus_keys: str | Path | None = None,
    live: tuple[str, int] | None = None,
    guard: GuardOptions | None = DEFAULT_GUARD,
    start_tolerance_m: float = START_TOLERANCE_M,
    transit: bool = False,
    signing_key: bytes | str | Path | None = None,
    drift_transit_m: float = DRIFT_TRANSIT_M,
) -> VehicleRunResult:
    """Fly ``flight`` (:class:`planner.fly.flight.Flight`) on the vehicle at ``connection`` (a pymavlink string).

    Raises a :class:`rapt.errors.RaptError` with one line when bring-up fails; by then nothing
    has been commanded that the failed check could have prevented.  ``timeout_s`` bounds the
    run's wall time (None: the mission's time limit on the vehicle's clock ends it).
    ``record_only`` names watchdog reasons (:data:`planner.fly.vehicle.watchdog.REASONS`) that are logged
    as violations without taking control, e.g. ``nogo`` where the no-go areas are virtual.
    ``bus_keys``: the range's keys directory; each part then joins the secure bus as its role
    (:data:`planner.fly.run_bus.PART_ROLES`), the bridge's session being the hub. ``live``: ``(host, port)``
    of a Foxglove live view of the run (:class:`bridge.live_process.LiveViewProcess`). ``guard``: the onboard
    guard bring-up installs (:mod:`planner.fly.vehicle.guard`); None flies without one, and the timeline says so.
    A vehicle farther than ``start_tolerance_m`` from the scenario's start is flown there before the scenario
    clock starts when it is within ``drift_transit_m`` (a current moved it) or with ``transit``, and refused otherwise; one still armed from an earlier run is surfaced and disarmed first.
    ``signing_key`` (32 bytes, or a key file): MAVLink 2 signing, the key given to the vehicle at bring-up.
    """
    _check_options(action, record_only, connection)
    mission, u = flight.mission, np.asarray(flight.u, dtype=float)
    scen = make_scenarios(mission, u[None, :])
    if not scen.valid[0]:
        raise InputError(
            f"--scenario {flight.scenario_id}: invalid for mission '{mission.name}' ({scen.invalid_reason[0]})"
        )
    reader = log_path is not None or live is not None
    roles = (keys.DEFAULT_ACTIVE, keys.WATCHDOG_SOURCE, "operator") + (("logger",) if reader else ())
    bus = RunBus(bus_keys, vehicle=vehicle, roles=roles)  # every key checked before anything joins
    parts: list = []
    bringup = None
    started = time.perf_counter()
    try:
        view = start_live_view(bus, vehicle, mission, u, live)
        if view is not None:
            parts.append(view)  # closed last: it shows the run's end
        run = _start_parts(bus, vehicle, flight, connection, log_path, action, record_only, parts, signing_key)
        meta = scenario_json(
            mission,
            u,
            mission_file=flight.mission_file,
            scenario_id=flight.scenario_id,
            plan_id=flight.plan_id,
            vehicle_link=connection,
            legs=flight.legs,
        )
        bus.put(PART_ROLES["scenario_meta"], keys.meta(vehicle, SCENARIO_META), meta, when_heard=log_path is not None)
        bringup = BringUp(
            run.bridge,
            bus.session(PART_ROLES["bringup"]),
            vehicle,
            mission,
            connection,
            timeouts or BringUpTimeouts(),
            say,
            route=flight.route,
            guard_options=guard,
            start_tolerance_m=start_tolerance_m,
            transit=transit,
            drift_transit_m=drift_transit_m,
        )
        try:
            start_ms = bringup.run()
            run.begin(start_ms)
            bus.put(PART_ROLES["control"], keys.active(vehicle), keys.DEFAULT_ACTIVE, when_heard=True)
            ended = _fly(run.referee, run.watchdog, run.bridge, timeout_s)
        except BaseException as exc:  # Ctrl-C, or a bring-up step that failed after GUIDED and arming
            _stop(exc, run, bringup, say)
            raise
        _land(ended, run, bringup, action, say)
        wall = time.perf_counter() - started
        return _result(run, bringup, ended, wall, start_ms, log_path)
    finally:
        if bringup is not None:
            bringup.close()
        for part in reversed(parts):
            part.close()
        bus.close()


def _check_options(action: str, record_only: Iterable[str], connection: str) -> None:
    """InputError (one line) for an unknown watchdog action or reason, or an empty connection string."""
    if action not in WATCHDOG_ACTIONS:
        raise InputError(f"--watchdog-action: expected one of {', '.join(WATCHDOG_ACTIONS)}, got {action!r}")
    unknown = sorted(set(record_only) - set(REASONS))
    if unknown:
        raise InputError(f"--watchdog-record: unknown reason {unknown[0]!r}; known: {', '.join(REASONS)}")
    if not isinstance(connection, str) or not connection.strip():
        raise InputError("--mavlink: expected a pymavlink connection string such as tcp:127.0.0.1:5760")


@dataclass
class _Parts:
    """The parts of a run that follow the vehicle, started on its bus."""

    bridge: MavlinkBridge
    virtual: VirtualRange
    referee: Referee
    backseat: BackSeat
    watchdog: Watchdog

    def begin(self, start_ms: int) -> None:
        """Start the scenario clock at the vehicle's ``time_boot_ms`` = ``start_ms`` (the bring-up is done)."""
        self.virtual.begin()
        self.referee.begin(start_ms)
        self.backseat.begin(start_ms)
        self.watchdog.begin()


def _start_parts(
    bus: RunBus,
    vehicle: str,
    flight,
    connection: str,
    log_path: str | Path | None,
    action: str,
    record_only: Iterable[str],
    parts: list,
    signing_key: bytes | str | Path | None = None,
) -> _Parts:
    """Start the logger (with the scenario's map), the bridge, the virtual range, the referee, the back-seat and
    the watchdog, each added to ``parts`` (to be closed); return once their subscriptions are at the hub."""
    mission, u = flight.mission, np.asarray(flight.u, dtype=float)
    heard = [keys.DEFAULT_ACTIVE, keys.WATCHDOG_SOURCE]
    if log_path is not None:
        from bridge.logger import McapLogger

        # the map is put when the logger appears
        parts.append(ScenarioMap(bus.session(PART_ROLES["scenario_map"]), vehicle, mission, u).start())
        logger = McapLogger(log_path, bus.session(PART_ROLES["logger"]), vehicle=vehicle, roles=bus.put_roles())
        parts.append(logger.start())
        heard.append("logger")
    hub = bus.session("bridge")
    bridge = MavlinkBridge(
        connection,
        hub,
        vehicle=vehicle,
        allow_commands=True,
        required_mode="GUIDED",
        signing_key=signing_key,
        accept_unsigned=signing_key is not None,  # until bring-up has given the vehicle the key
    ).start()
    parts.append(bridge)
    virtual = VirtualRange(bus.session(PART_ROLES["virtual_range"]), vehicle, mission, u).start()
    referee = Referee(bus.session(PART_ROLES["referee"]), vehicle, mission, u).start()
    backseat = BackSeat(
        bus.session(PART_ROLES["backseat"]), vehicle, mission, u, pacing="vehicle", legs=flight.legs
    ).start()
    rules = WatchdogRules(record_only=frozenset(record_only))
    watchdog = Watchdog(
        bus.session(PART_ROLES["watchdog"]), vehicle, mission, u, bridge, action=action, rules=rules
    ).start()
    parts += [virtual, referee, backseat, watchdog]
    bus.wait_for_parts(*heard)  # their subscriptions are at the hub before the bring-up's first put
    return _Parts(bridge, virtual, referee, backseat, watchdog)


def _stop(exc: BaseException, run: _Parts, bringup: BringUp, say) -> None:
    """The run stopped before its end (``exc``): end it, stop commanding, and recover the vehicle if it is ours."""
    run.referee.end("stopped by the operator" if isinstance(exc, KeyboardInterrupt) else f"stopped: {exc}")
    run.backseat.close()
    run.watchdog.close()
    hb = run.bridge.autopilot
    left = _left_guided(hb) if hb is not None and hb.armed else ""
    if bringup.took_control and left:  # a failsafe or a pilot has it now
        bringup.note("recover", "ok", f"nothing commanded: {VEHICLE_ENDED}{left}")
    elif bringup.took_control:  # never touch a vehicle the checks refused: someone else may fly it
        _recover(run.bridge, run.referee, bringup, "surface", say)


def _land(ended: str, run: _Parts, bringup: BringUp, action: str, say) -> None:
    """After the run's end: no more set-points; surface (or hold) the vehicle unless it took itself back."""
    run.backseat.close()  # the run is over: no more set-points of the scenario's
    run.watchdog.close()
    if ended.startswith(VEHICLE_ENDED):  # the vehicle, a failsafe or a pilot took it: command nothing
        bringup.note("recover", "ok", f"nothing commanded: {ended}")
    else:
        recovery = "hold" if run.watchdog.intervention and action == "hold" else "surface"
        _recover(run.bridge, run.referee, bringup, recovery, say)


def _result(
    run: _Parts, bringup: BringUp, ended: str, wall: float, start_ms: int, log_path: str | Path | None
) -> VehicleRunResult:
    """The run's result, scored by the referee; once the last reports had time to reach the logger."""
    backseat, watchdog = run.backseat, run.watchdog
    autonomy = backseat.autonomy
    track = run.referee.track()
    scores = run.referee.scorer.scores([bool(v) for v in autonomy.wp_aborted[0]], int(autonomy.return_reason[0]))
    time.sleep(0.3)  # the last reports reach the logger
    return VehicleRunResult(
        scores,
        track,
        ended,
        watchdog.intervention or "",
        float(track[-1, 0]) if len(track) else 0.0,
        wall,
        start_ms,
        backseat.stats.as_dict(),
        dict(vars(backseat.telemetry.counts)),
        list(bringup.timeline),
        dict(run.bridge.stats),
        Path(log_path) if log_path else None,
        list(backseat.stats.ticks),
        list(backseat.stats.input_age_ms),
        dict(watchdog.violations),
        run.virtual.stats,
    )


#: Watchdog reasons the referee also calls from its track rows (the scenario's virtual battery empty,
#: an obstacle touched, out of the area).  The watchdog acts on the first report that breaks one;
#: the referee's next row, at most one period later, then ends the run as the scenario's own outcome,
#: the end the plan predicts.  When that row does not (the vehicle's real pack, a touch between
#: rows), the run ends as the watchdog's.
REFEREED = (BATTERY, COLLISION, OPERATIONAL_AREA)


def _fly(referee: Referee, watchdog: Watchdog, bridge: MavlinkBridge, timeout_s: float | None) -> str:
    """Wait for the run's end: the referee's, the watchdog's, the vehicle's own, or the wall-time limit's."""
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    period_ms = int(round(referee.mission.dt * 1000))
    grace: tuple[int, float] | None = None  # (vehicle ms, wall deadline) the referee has to call it
    while True:
        if referee.ended:
            return referee.ended
        if watchdog.intervention:
            now_ms = referee.telemetry.now_ms
            if grace is None and watchdog.intervention in REFEREED and now_ms >= 0:
                grace = (now_ms + period_ms + 100, time.monotonic() + period_ms / 1000.0 + 1.0)
            if grace is None or now_ms > grace[0] or time.monotonic() > grace[1]:
                reason = f"watchdog: {watchdog.intervention}"
                referee.end(reason)
                return reason
            time.sleep(0.02)
            continue  # the vehicle leaving GUIDED now is the watchdog's doing, not a pilot's
        taken = _taken_by_vehicle(bridge)
        if taken:
            reason = f"{VEHICLE_ENDED}{taken}"
            referee.end(reason)
            return reason
        if deadline is not None and time.monotonic() > deadline:
            reason = f"wall-time limit of {timeout_s:g} s"
            referee.end(reason)
            return reason
        time.sleep(0.02)


#: How a run ends that the vehicle ended: a failsafe disarmed it or changed its mode, or a pilot took it.
VEHICLE_ENDED = "vehicle: "


def _taken_by_vehicle(bridge: MavlinkBridge) -> str:
    """Why the vehicle is no longer ours to fly, from its heartbeat ("" while it is armed in GUIDED).

    ArduSub's failsafes (ground station lost, leak, battery, EKF) disarm it or switch its mode,
    and a safety pilot takes it in a mode of their own; in each case the run is over and
    nothing more is commanded: the vehicle, or the person, now in charge is not fought."""
    hb = bridge.autopilot
    if hb is not None and not hb.armed:
        return "disarmed itself (a failsafe, or disarmed by someone else)"
    return _left_guided(hb)


def _left_guided(hb: Autopilot | None) -> str:
    """Why the vehicle is out of GUIDED by the heartbeat ``hb`` ("" while in GUIDED or not heard)."""
    if hb is None or hb.custom_mode == GUIDED:
        return ""
    return f"left GUIDED (now {hb.mode_label}: a failsafe, or a pilot took it)"


def _recover(bridge: MavlinkBridge, referee: Referee, bringup: BringUp, action: str, say) -> None:
    """After the run (or on Ctrl-C): SURFACE, wait for the surface, disarm; or leave it holding in GUIDED."""
    hb = bridge.autopilot
    if hb is None or not hb.armed:
        return
    if action == "hold":
        bringup.note("recover", "ok", "left holding in GUIDED for the operator (watchdog action: hold)")
        return
    try:
        bridge.set_mode("SURFACE")
        deadline = time.monotonic() + bringup.timeouts.surface
        while time.monotonic() < deadline:
            pose = referee.telemetry.pose
            if pose is not None and pose.surfaced:
                break
            time.sleep(0.05)
    except Exception as exc:  # a lost link or a refusal must not keep us from disarming
        bringup.note("recover", "failed", f"SURFACE: {exc}")
    try:
        bridge.arm(False)
        bringup.note("recover", "ok", "surfaced and disarmed")
    except Exception as exc:
        bringup.note("recover", "failed", f"disarm: {exc}; the vehicle's own failsafe must act")
