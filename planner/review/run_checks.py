"""Automatic checks of a run's log: was the run itself sound, so that what it observed counts?

``compare`` says whether the predicted mode held; these say whether the run that showed it
can be trusted, as PX4's Flight Review does for every upload and no ArduSub tool does for a
test run. Each check is named, gives a verdict (``pass``, ``warn``, ``fail``, or ``unknown``
when the log lacks what it needs, with the reason), the evidence (the time in scenario
seconds, the value and the threshold it was held against) and a one-line reason.

=================  ===========================================================================
check              fails when (warns when)
=================  ===========================================================================
``estimator``      EKF_STATUS_REPORT without attitude or horizontal velocity, or uninitialised,
                   or a velocity, position or compass variance >= 0.8, ArduPilot's EKF
                   failsafe threshold (variance >= 0.5, or a GPS glitch flagged)
``position``       no position report for 3 s, or the EKF without a horizontal position
                   (constant-position mode) (a gap of 1 s)
``link``           more than 1 % of the vehicle's frames lost on the way to the log, or any
                   publication lost on the bus (any frame lost); per source, from ``rapt.losses``
``setpoints``      a gap of 3 s of vehicle time between the flying source's set-points: ArduSub
                   GUIDED stops the vehicle then (1.5 s)
``thrusters``      never: saturation is a fact about the run, not a fault (thrusters at their
                   PWM limits, MOT_PWM_MIN/MAX where the log has them, for 10 % of the flight)
``depth``          deeper than the running depth by 3 m (by 1 m)
``pack``           a cell below 3.3 V (3.5 V) or a 20 % drop within 2 s (10 %), the cell count
                   from the voltage at the start
``gauge``          the virtual fuel gauge rising, or silent for 10 s (5 s), where the scenario
                   has one
``statustext``     a failsafe, or a message of severity ERROR or worse (WARNING)
``modes``          a mode change or disarm nobody commanded (no accepted command within 2 s)
``watchdog``       the watchdog took the vehicle over before the run's end (a rule recorded
                   without taking over)
=================  ===========================================================================

Everything is judged over the flight: from the scenario clock's start (the bring-up's end) to
the referee's end, or over the whole log for a lock-step run. :class:`RunEvidence` gathers what
the checks need in the log reader's single pass (:class:`planner.review.logs.RunLogReader`);
:func:`run_checks` judges it. A run with a failed check does not count towards the bias fit
unless the user keeps it (``rapt-plan compare --keep-failed``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from planner.common.telemetry import VIRTUAL_BATTERY_ID
from sim.uuv.interface import DEPTH_M

__all__ = ["Check", "RunEvidence", "run_checks", "verdict_of", "VERDICTS", "CHECKS", "summary_line"]

#: Verdicts from best to worst; ``unknown`` ranks as a warning when verdicts are combined.
VERDICTS = ("pass", "warn", "fail", "unknown")
_RANK = {"pass": 0, "unknown": 1, "warn": 1, "fail": 2}

# EKF_STATUS_REPORT flags (MAVLink EKF_STATUS_FLAGS)
EKF_ATTITUDE, EKF_VELOCITY_HORIZ, EKF_POS_HORIZ_REL, EKF_POS_HORIZ_ABS = 1, 2, 8, 16
EKF_CONST_POS_MODE, EKF_UNINITIALIZED, EKF_GPS_GLITCH = 128, 1024, 32768
#: ArduPilot's EKF failsafe threshold (FS_EKF_THRESH's default) and where Mission Planner turns a variance amber.
VARIANCE_FAIL, VARIANCE_WARN = 0.8, 0.5
POSITION_GAP_FAIL_S, POSITION_GAP_WARN_S = 3.0, 1.0
LINK_LOST_FAIL = 0.01
#: ArduSub drops a GUIDED velocity set-point after 3 s (GUIDED's timeout) and holds still.
SETPOINT_GAP_FAIL_S, SETPOINT_GAP_WARN_S = 3.0, 1.5
#: ArduSub's default thruster PWM range (MOT_PWM_MIN, MOT_PWM_MAX).
PWM_LIMITS = (1100, 1900)
SATURATED_WARN = 0.10
DEPTH_FAIL_M, DEPTH_WARN_M = 3.0, 1.0
#: Lithium cells: full charge, and the voltages below which a pack is sagging (warn) or damaged (fail).
CELL_FULL_V, CELL_WARN_V, CELL_FAIL_V = 4.25, 3.5, 3.3
#: A pack under a thruster's load step drops ~6 % at once on ArduSub SITL's BlueROV2 (internal resistance): normal.
SAG_WINDOW_S, SAG_FAIL, SAG_WARN = 2.0, 0.20, 0.10
GAUGE_SILENT_FAIL_S, GAUGE_SILENT_WARN_S = 10.0, 5.0
MODE_ACK_S = 2.0
#: A failsafe's words and mode change come as the run ends, reported a moment after its last position.
END_GRACE_S = 2.0
MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM = 176, 400
MAV_SAFETY_ARMED = 128
#: Words of a failsafe in a STATUSTEXT: ArduPilot's own, and ArduSub's GCS failsafe ("MYGCS: 255, heartbeat lost").
FAILSAFE_WORDS = ("failsafe", "fail-safe", "heartbeat lost")


@dataclass
class Check:
    """One check's verdict on a run, with its evidence (time in scenario seconds, value, threshold)."""

    name: str
    verdict: str
    reason: str
    time_s: float | None = None
    value: float | str | None = None
    threshold: float | str | None = None

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


def verdict_of(checks: list[Check] | list[dict]) -> str:
    """The worst verdict (``fail`` > ``warn``/``unknown`` > ``pass``); ``pass`` for no checks."""
    verdicts = [c.verdict if isinstance(c, Check) else c["verdict"] for c in checks]
    worst = max(verdicts, key=_RANK.__getitem__, default="pass")
    return "warn" if worst == "unknown" else worst


def summary_line(checks: list[dict]) -> str:
    """``fail: setpoints, modes`` / ``warn: thrusters`` / ``pass``: the worst verdict and the checks that gave it."""
    verdict = verdict_of(checks)
    if verdict == "pass":
        return "pass"
    names = [c["name"] for c in checks if _RANK[c["verdict"]] == _RANK[verdict]]
    return f"{verdict}: {', '.join(names)}"


@dataclass
class RunEvidence:
    """What the checks need from a log, gathered message by message (vehicle times in ms since boot)."""

    now_ms: int = 0  # the latest vehicle time seen (messages without their own take it)
    positions: list[int] = field(default_factory=list)  # GLOBAL_POSITION_INT times
    depth: list[tuple[int, float]] = field(default_factory=list)
    ekf: list[tuple[int, int, float, float, float]] = field(default_factory=list)  # ms, flags, vel, pos, compass
    servo: list[tuple[int, tuple[int, ...]]] = field(default_factory=list)
    volts: list[tuple[int, float]] = field(default_factory=list)
    gauge: list[tuple[int, float]] = field(default_factory=list)  # the virtual gauge's energy consumed (hJ)
    texts: list[tuple[int, int, str]] = field(default_factory=list)
    modes: list[tuple[int, int, bool, int]] = field(default_factory=list)  # changes: ms, custom_mode, armed, log ns
    acks: list[tuple[int, int]] = field(default_factory=list)  # accepted mode/arming commands: log ns, command
    paced: bool = True  # the vehicle keeps its own pace (False: a lock-step front-seat that waits for us)
    params: dict[str, float] = field(default_factory=dict)
    clock: list[tuple[int, int]] = field(default_factory=list)  # (log ns, vehicle ms) of position reports
    setpoints: dict[str, list[int]] = field(default_factory=dict)  # source -> log ns of its set-points
    watchdog: list[dict] = field(default_factory=list)
    start_ms: int | None = None
    end_ms: int | None = None
    first_ms: int | None = None
    lost_log_ns: list[tuple[int, int]] = field(default_factory=list)  # log-time spans of chunks the log lost
    _mode: tuple[int, bool] | None = None

    def on_mavlink(self, m, log_ns: int) -> None:
        """One decoded MAVLink message from the vehicle (or the virtual range)."""
        kind = m.get_type()
        t = getattr(m, "time_boot_ms", None)
        if isinstance(t, int) and t > 0:
            self.now_ms = max(self.now_ms, t)
            if self.first_ms is None:
                self.first_ms = t
        ms = self.now_ms
        if kind == "GLOBAL_POSITION_INT":
            self.positions.append(ms)
            self.depth.append((ms, -m.relative_alt / 1000.0))
            self.clock.append((log_ns, ms))
        elif kind == "EKF_STATUS_REPORT":
            self.ekf.append((ms, m.flags, m.velocity_variance, m.pos_horiz_variance, m.compass_variance))
        elif kind == "SERVO_OUTPUT_RAW":
            self.servo.append((ms, tuple(getattr(m, f"servo{i}_raw") for i in range(1, 9))))
        elif kind == "SYS_STATUS" and 0 < m.voltage_battery < 65535:
            self.volts.append((ms, m.voltage_battery / 1000.0))
        elif kind == "BATTERY_STATUS" and m.id == VIRTUAL_BATTERY_ID and m.energy_consumed >= 0:
            self.gauge.append((ms, float(m.energy_consumed)))
        elif kind == "STATUSTEXT":
            text = str(m.text).rstrip("\x00")
            self.texts.append((ms, int(m.severity), text))
            if text.startswith("run ended:") and self.end_ms is None:  # a lock-step front-seat's own end
                self.end_ms = ms
        elif kind == "HEARTBEAT" and m.autopilot != 8:  # MAV_AUTOPILOT_INVALID: not the vehicle's own
            state = (int(m.custom_mode), bool(m.base_mode & MAV_SAFETY_ARMED))
            if state != self._mode:
                if self._mode is not None:
                    self.modes.append((ms, *state, log_ns))
                self._mode = state
        elif (
            kind == "COMMAND_ACK" and m.result == 0 and m.command in (MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM)
        ):
            self.acks.append((log_ns, int(m.command)))
        elif kind == "PARAM_VALUE":
            self.params[str(m.param_id).rstrip("\x00")] = float(m.param_value)

    def on_setpoint(self, source: str, log_ns: int) -> None:
        self.setpoints.setdefault(source, []).append(log_ns)

    def on_event(self, source: str, obj: dict) -> None:
        if source == "watchdog":
            self.watchdog.append(obj)
        elif source == "referee" and obj.get("ended") and isinstance(obj.get("time_boot_ms"), int):
            self.end_ms = int(obj["time_boot_ms"])

    def on_clock(self, start_ms: int) -> None:
        self.start_ms = int(start_ms)


class _Window:
    """The flight's span in vehicle ms, and scenario seconds of a vehicle time."""

    def __init__(self, ev: RunEvidence):
        self.t0 = ev.start_ms if ev.start_ms is not None else (ev.first_ms or 0)
        self.t1 = ev.end_ms if ev.end_ms is not None else ev.now_ms

    def __contains__(self, ms: int) -> bool:
        return self.t0 <= ms <= self.t1

    def s(self, ms: float) -> float:
        return round(float(ms - self.t0) / 1000.0, 3)


Judge = Callable[[RunEvidence, _Window, "dict | None"], Check]


def _estimator(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [r for r in ev.ekf if r[0] in w]
    if not rows:
        return Check("estimator", "unknown", "the vehicle streamed no EKF_STATUS_REPORT during the flight")
    for ms, flags, *_ in rows:
        if not (flags & EKF_ATTITUDE and flags & EKF_VELOCITY_HORIZ) or flags & EKF_UNINITIALIZED:
            return Check(
                "estimator", "fail", "the EKF lost attitude or horizontal velocity", w.s(ms), flags, "flags 1|2"
            )
    names = ("velocity", "horizontal position", "compass")
    worst = max(((v, k, ms) for ms, _, *var in rows for k, v in enumerate(var)), key=lambda x: x[0])
    value, k, ms = worst
    text = f"EKF {names[k]} variance {value:.2f}"
    if value >= VARIANCE_FAIL:
        return Check("estimator", "fail", f"{text}: at ArduPilot's EKF failsafe", w.s(ms), value, VARIANCE_FAIL)
    glitch = next((ms for ms, flags, *_ in rows if flags & EKF_GPS_GLITCH), None)
    if value >= VARIANCE_WARN:
        return Check("estimator", "warn", f"{text}: the estimate is doubtful", w.s(ms), value, VARIANCE_WARN)
    if glitch is not None:
        return Check("estimator", "warn", "the EKF flagged a GPS glitch", w.s(glitch), "gps glitch", "none")
    return Check(
        "estimator", "pass", f"healthy; largest variance {value:.2f} ({names[k]})", w.s(ms), value, VARIANCE_WARN
    )


def _position(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    times = np.array([ms for ms in ev.positions if ms in w], dtype=float)
    if times.size < 2:
        return Check("position", "unknown", "fewer than two position reports (GLOBAL_POSITION_INT) in the flight")
    lost = next(
        (ms for ms, flags, *_ in ev.ekf if ms in w and (flags & EKF_CONST_POS_MODE or not flags & EKF_POS_HORIZ_REL)),
        None,
    )
    if lost is not None:
        return Check(
            "position",
            "fail",
            "the EKF had no horizontal position (constant-position mode)",
            w.s(lost),
            "const_pos_mode",
            "none",
        )
    points = np.concatenate([[w.t0], times, [w.t1]])  # the flight's first and last moments count too
    gaps = np.diff(points) / 1000.0
    k = int(np.argmax(gaps))
    gap, at = float(gaps[k]), w.s(points[k])
    period = float(np.median(np.diff(times))) / 1000.0  # a vehicle reporting every 2 s is not losing them
    limits = (("fail", max(POSITION_GAP_FAIL_S, 5 * period)), ("warn", max(POSITION_GAP_WARN_S, 2.5 * period)))
    for verdict, limit in limits:
        if gap > limit:
            return Check("position", verdict, f"no position report for {gap:.1f} s", at, round(gap, 3), limit)
    return Check("position", "pass", f"reported throughout; longest gap {gap:.2f} s", at, round(gap, 3), limits[1][1])


def _link(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    if losses is None:
        return Check("link", "unknown", "the log has no loss record (rapt.losses): its logger did not finish")
    received = max(int(losses.get("received") or 0), 1)
    link, bus = losses.get("link_lost"), int(losses.get("bus_lost") or 0)
    by_source = losses.get("link_lost_by_source") or {}
    worst = max(by_source.items(), key=lambda kv: kv[1], default=(None, 0))
    where = f" (most from {worst[0]}: {worst[1]})" if worst[0] is not None and worst[1] else ""
    if not isinstance(link, int):
        return Check("link", "unknown", f"the bridge reported no link counters; bus lost {bus}", None, bus, 0)
    share = link / received
    if share > LINK_LOST_FAIL or bus > 0:
        return Check(
            "link",
            "fail",
            f"{link} frame(s) lost on the link{where}, {bus} on the bus",
            None,
            round(share, 5),
            LINK_LOST_FAIL,
        )
    if link > 0:
        return Check("link", "warn", f"{link} frame(s) lost on the link{where}", None, round(share, 5), 0)
    return Check("link", "pass", f"no frame lost of {received}", None, 0, 0)


def _vehicle_ms(ev: RunEvidence, log_ns: list[int]) -> np.ndarray:
    """Log times put on the vehicle's clock through the position reports' (log time, vehicle time) pairs."""
    if len(ev.clock) < 2:
        return np.array([], dtype=float)
    wall, ms = np.array(ev.clock, dtype=float).T
    return np.interp(np.asarray(log_ns, dtype=float), wall, ms)


def _setpoints(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    if not ev.paced:
        return Check("setpoints", "pass", "lock-step: the simulated front-seat waits for every set-point")
    if not ev.setpoints:
        return Check("setpoints", "unknown", "no back-seat set-points in the log")
    source = "autonomy" if "autonomy" in ev.setpoints else max(ev.setpoints, key=lambda k: len(ev.setpoints[k]))
    at = _vehicle_ms(ev, ev.setpoints[source])
    at = at[(at >= w.t0) & (at <= w.t1)]
    if at.size < 2:
        return Check("setpoints", "unknown", f"fewer than two set-points of {source} in the flight")
    at = np.append(at, max(w.t1, at[-1]))  # silence up to the flight's end counts too
    gaps = np.diff(at) / 1000.0
    k = int(np.argmax(gaps))
    gap = float(gaps[k])
    for verdict, limit in (("fail", SETPOINT_GAP_FAIL_S), ("warn", SETPOINT_GAP_WARN_S)):
        if gap > limit:
            why = (
                "past ArduSub's 3 s GUIDED timeout: the vehicle held still"
                if verdict == "fail"
                else "half the 3 s GUIDED timeout"
            )
            return Check(
                "setpoints",
                verdict,
                f"{source} sent no set-point for {gap:.1f} s ({why})",
                w.s(at[k]),
                round(gap, 3),
                limit,
            )
    return Check(
        "setpoints",
        "pass",
        f"{source} kept the vehicle's set-point alive; longest gap {gap:.2f} s",
        w.s(at[k]),
        round(gap, 3),
        SETPOINT_GAP_WARN_S,
    )


def _thrusters(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [(ms, out) for ms, out in ev.servo if ms in w]
    if not rows:
        return Check("thrusters", "unknown", "the vehicle streamed no SERVO_OUTPUT_RAW")
    out = np.array([o for _, o in rows], dtype=float)
    moving = [j for j in range(out.shape[1]) if np.ptp(out[:, j]) > 0 and out[:, j].max() > 0]  # thrusters move
    if not moving:
        return Check("thrusters", "unknown", "no servo output moved during the flight")
    lo = ev.params.get("MOT_PWM_MIN", PWM_LIMITS[0])
    hi = ev.params.get("MOT_PWM_MAX", PWM_LIMITS[1])
    source = "MOT_PWM_MIN/MAX" if "MOT_PWM_MIN" in ev.params else "ArduSub's default limits"
    at_limit = ((out[:, moving] <= lo) | (out[:, moving] >= hi)).any(axis=1)
    share = float(at_limit.mean())
    first = w.s(rows[int(np.argmax(at_limit))][0]) if at_limit.any() else None
    verdict = "warn" if share > SATURATED_WARN else "pass"
    return Check(
        "thrusters",
        verdict,
        f"a thruster at its limit ({lo:.0f}/{hi:.0f} us, {source}) for {share:.0%} of the flight",
        first,
        round(share, 4),
        SATURATED_WARN,
    )


def _depth(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [(ms, d) for ms, d in ev.depth if ms in w]
    if not rows:
        return Check("depth", "unknown", "no depth in the flight's position reports")
    ms, deepest = max(rows, key=lambda r: r[1])
    over = deepest - DEPTH_M
    for verdict, limit in (("fail", DEPTH_FAIL_M), ("warn", DEPTH_WARN_M)):
        if over > limit:
            return Check(
                "depth",
                verdict,
                f"{deepest:.1f} m deep, {over:.1f} m below the running depth",
                w.s(ms),
                round(deepest, 2),
                DEPTH_M + limit,
            )
    return Check(
        "depth",
        "pass",
        f"deepest {deepest:.1f} m (running depth {DEPTH_M:g} m)",
        w.s(ms),
        round(deepest, 2),
        DEPTH_M + DEPTH_WARN_M,
    )


def _pack(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [(ms, v) for ms, v in ev.volts if ms in w]
    if len(rows) < 2:
        return Check("pack", "unknown", "no pack voltage (SYS_STATUS) in the flight")
    t, v = np.array(rows, dtype=float).T
    cells = max(1, math.ceil(v[0] / CELL_FULL_V))
    k = int(np.argmin(v))
    cell = float(v[k] / cells)
    back = np.searchsorted(t, t - SAG_WINDOW_S * 1000.0)  # the voltage SAG_WINDOW_S before each report
    drop = np.array([(v[max(b, 0) : i + 1].max() - v[i]) / v[0] for i, b in enumerate(back)])
    j = int(np.argmax(drop))
    low, sag = f"{cell:.2f} V a cell ({cells} cells)", f"the pack sagged {drop[j]:.0%} within {SAG_WINDOW_S:g} s"
    # without a virtual gauge the pack is the scenario's battery, and running it down may be the scenario
    scenario_pack = not ev.gauge
    flat = f"{low}: below {CELL_FAIL_V} V" + (" (the pack is the scenario's battery)" if scenario_pack else "")
    ladder = (  # worst first: (verdict, found, reason, at, value, threshold)
        ("warn" if scenario_pack else "fail", cell < CELL_FAIL_V, flat, t[k], round(cell, 3), CELL_FAIL_V),
        ("fail", drop[j] > SAG_FAIL, sag, t[j], round(float(drop[j]), 4), SAG_FAIL),
        ("warn", cell < CELL_WARN_V, f"{low}: below {CELL_WARN_V} V", t[k], round(cell, 3), CELL_WARN_V),
        ("warn", drop[j] > SAG_WARN, sag, t[j], round(float(drop[j]), 4), SAG_WARN),
    )
    for verdict, found, reason, at, value, threshold in ladder:
        if found:
            return Check("pack", verdict, reason, w.s(at), value, threshold)
    return Check("pack", "pass", f"lowest {cell:.2f} V a cell ({cells} cells)", w.s(t[k]), round(cell, 3), CELL_WARN_V)


def _gauge(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [(ms, e) for ms, e in ev.gauge if ms in w]
    if not rows:
        return Check("gauge", "pass", "no virtual fuel gauge in this run (the vehicle's own pack is the scenario's)")
    t, e = np.array(rows, dtype=float).T
    rises = np.flatnonzero(np.diff(e) < 0)  # consumed energy falling: the gauge ran backwards
    if rises.size:
        k = int(rises[0]) + 1
        return Check(
            "gauge", "fail", "the virtual gauge's consumed energy went down", w.s(t[k]), float(e[k]), float(e[k - 1])
        )
    gaps = np.diff(np.concatenate([t, [w.t1]])) / 1000.0
    k = int(np.argmax(gaps))
    for verdict, limit in (("fail", GAUGE_SILENT_FAIL_S), ("warn", GAUGE_SILENT_WARN_S)):
        if gaps[k] > limit:
            return Check(
                "gauge",
                verdict,
                f"the virtual gauge was silent for {gaps[k]:.1f} s",
                w.s(t[k]),
                round(float(gaps[k]), 3),
                limit,
            )
    return Check(
        "gauge",
        "pass",
        f"the virtual gauge reported throughout; longest gap {gaps[k]:.1f} s",
        w.s(t[k]),
        round(float(gaps[k]), 3),
        GAUGE_SILENT_WARN_S,
    )


def _statustext(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    rows = [r for r in ev.texts if w.t0 <= r[0] <= w.t1 + END_GRACE_S * 1000]  # what ended the run says so after
    bad = [r for r in rows if r[1] <= 3 or any(word in r[2].lower() for word in FAILSAFE_WORDS)]
    if bad:
        ms, severity, text = bad[0]
        return Check(
            "statustext",
            "fail",
            f"the vehicle said {text!r} (severity {severity})",
            w.s(ms),
            text,
            "severity > 3, no failsafe",
        )
    warned = [r for r in rows if r[1] == 4]
    if warned:
        ms, severity, text = warned[0]
        return Check("statustext", "warn", f"the vehicle warned {text!r}", w.s(ms), text, "severity > 4")
    return Check(
        "statustext",
        "pass",
        f"{len(rows)} message(s), none a failsafe, error or warning",
        None,
        len(rows),
        "severity > 4",
    )


def _modes(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    """A change is commanded when an accepted mode or arming command's ACK came within MODE_ACK_S of it, on the
    log's clock (a lock-step front-seat's clock races ahead of its heartbeats)."""
    # on a vehicle a change that ended the run counts (a recovery is acked); a lock-step front-seat ends its
    # scenario itself, disarming as it says "run ended"
    last = w.t1 + END_GRACE_S * 1000 if ev.paced else w.t1 - 1
    for ms, mode, armed, log_ns in ev.modes:
        if not w.t0 <= ms <= last:
            continue
        commanded = any(abs(log_ns - a) <= MODE_ACK_S * 1e9 for a, _ in ev.acks)
        if not commanded:
            what = f"custom mode {mode}, {'armed' if armed else 'disarmed'}"
            return Check(
                "modes", "fail", f"the vehicle changed to {what} without a command", w.s(ms), what, "commanded"
            )
    return Check("modes", "pass", "every mode change in the flight was commanded", None, len(ev.modes), "commanded")


def _watchdog(ev: RunEvidence, w: _Window, losses: dict | None) -> Check:
    took = [e for e in ev.watchdog if e.get("event") == "intervention"]
    recorded = [e for e in ev.watchdog if e.get("event") == "violation"]

    def when(e: dict) -> float | None:
        return w.s(e["time_boot_ms"]) if isinstance(e.get("time_boot_ms"), int) else None

    if took:
        e = took[0]
        detail = f" ({e['detail']})" if e.get("detail") else ""
        return Check(
            "watchdog",
            "warn",
            f"the watchdog took over: {e.get('reason')}{detail}",
            when(e),
            str(e.get("reason")),
            "no intervention",
        )
    if recorded:
        e = recorded[0]
        return Check(
            "watchdog",
            "warn",
            f"the watchdog recorded {e.get('reason')} without taking over",
            when(e),
            str(e.get("reason")),
            "no violation",
        )
    return Check("watchdog", "pass", "the watchdog did not intervene", None, 0, "no intervention")


#: The checks, in the order they are shown.
CHECKS: dict[str, Judge] = {
    "estimator": _estimator,
    "position": _position,
    "link": _link,
    "setpoints": _setpoints,
    "thrusters": _thrusters,
    "depth": _depth,
    "pack": _pack,
    "gauge": _gauge,
    "statustext": _statustext,
    "modes": _modes,
    "watchdog": _watchdog,
}


#: The checks whose verdict is a silence: one that spans a chunk the log lost may be the log's, not the run's.
GAP_CHECKS = ("position", "setpoints", "gauge")


def run_checks(evidence: RunEvidence, losses: dict | None) -> list[Check]:
    """Every check on ``evidence`` (and the logger's ``losses`` record); a check that cannot judge a damaged
    log says ``unknown`` with the reason, and the others still run. A silence that spans a chunk the log
    lost is ``unknown`` too: the gap may be in the file, not in the run."""
    window = _Window(evidence)
    out = []
    for name, judge in CHECKS.items():
        try:
            out.append(judge(evidence, window, losses))
        except Exception as exc:  # a log too damaged for this check: say so, keep the rest
            out.append(Check(name, "unknown", f"cannot judge this log ({type(exc).__name__}: {exc})"))
    if evidence.lost_log_ns and len(evidence.clock) >= 2:
        spans = _vehicle_ms(evidence, [n for span in evidence.lost_log_ns for n in span]).reshape(-1, 2)
        for i, c in enumerate(out):
            if c.name in GAP_CHECKS and c.verdict in ("warn", "fail") and isinstance(c.value, float):
                a = window.t0 + (c.time_s or 0.0) * 1000.0
                b = a + c.value * 1000.0
                if any(lo <= b and hi >= a for lo, hi in spans):
                    out[i] = Check(c.name, "unknown", f"{c.reason}, where the log lost a chunk", c.time_s, c.value)
    return out
