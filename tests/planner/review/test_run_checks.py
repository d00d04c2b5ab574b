"""The automatic run checks: each passes on a clean flight and fails on a flight made to break it."""

from __future__ import annotations

import pytest

from bridge.frames import mavlink2
from planner.common.telemetry import VIRTUAL_BATTERY_ID
from planner.review.run_checks import CHECKS, RunEvidence, run_checks, summary_line, verdict_of

M = mavlink2.MAVLink(None)
START_MS = 100_000
GOOD_FLAGS = 831  # attitude, velocities, horizontal and vertical positions, predicted positions
LOSSES = {"received": 10_000, "link_lost": 0, "bus_lost": 0, "link_lost_by_source": {}}


def _flight(
    seconds: float = 60.0,
    *,
    position_gap: tuple[float, float] | None = None,
    setpoint_gap: tuple[float, float] | None = None,
    volts: callable = lambda t: 12.6 - 0.005 * t,
    ekf: callable = lambda t: (GOOD_FLAGS, 0.05, 0.04, 0.02),
    gcs_lost_at: float | None = None,
    extra: callable = lambda ev, t, ms: None,
) -> RunEvidence:
    """A paced flight as the log reader would gather it: 10 Hz positions at the running depth, 1 Hz status,
    set-points every second, the virtual gauge at 2 Hz; ``*_gap`` = (from, to): none strictly between."""
    ev = RunEvidence()
    ev.on_mavlink(M.heartbeat_encode(12, 3, 128 | 1, 4, 4), 0)  # armed in GUIDED (4) before the clock starts
    ev.on_clock(START_MS)
    failsafe = False
    for k in range(int(seconds * 10) + 1):
        t = k / 10.0
        ms = START_MS + k * 100
        log_ns = 1_000_000_000 + k * 100_000_000
        if not (position_gap and position_gap[0] < t < position_gap[1]):
            ev.on_mavlink(M.global_position_int_encode(ms, 0, 0, -2000, -2000, 0, 0, 0, 0), log_ns)
        if k % 10 == 0:
            if not (setpoint_gap and setpoint_gap[0] < t < setpoint_gap[1]) and not failsafe:
                ev.on_setpoint("autonomy", log_ns + 20_000_000)
            flags, vv, pv, cv = ekf(t)
            ev.on_mavlink(M.ekf_status_report_encode(flags, vv, pv, 0.01, cv, 0.0), log_ns)
            ev.on_mavlink(M.sys_status_encode(0, 0, 0, 500, int(volts(t) * 1000), 500, 80, 0, 0, 0, 0, 0, 0), log_ns)
            ev.on_mavlink(M.servo_output_raw_encode(ms * 1000, 0, *[1500 + (k % 30) * 5] * 6, 0, 1500), log_ns)
            if gcs_lost_at is not None and t >= gcs_lost_at and not failsafe:  # ArduSub's GCS failsafe
                failsafe = True
                ev.on_mavlink(M.statustext_encode(2, b"GCS Failsafe"), log_ns)
            mode = (19, False) if failsafe else (4, True)  # SURFACE (19), disarmed
            ev.on_mavlink(M.heartbeat_encode(12, 3, 1 | (128 if mode[1] else 0), mode[0], 4), log_ns)
        if k % 5 == 0:
            battery = M.battery_status_encode(VIRTUAL_BATTERY_ID, 0, 0, 0, [65535] * 10, -1, -1, int(t * 10), -1, 80)
            ev.on_mavlink(battery, log_ns)
        extra(ev, t, ms)
    ev.on_event("referee", {"ended": "mission complete", "time_boot_ms": START_MS + int(seconds * 1000)})
    return ev


def _by_name(ev: RunEvidence, losses: dict | None = LOSSES) -> dict:
    return {c.name: c for c in run_checks(ev, losses)}


def test_a_clean_flight_passes_every_check():
    checks = _by_name(_flight())
    assert list(checks) == list(CHECKS)
    assert {n: c.verdict for n, c in checks.items()} == dict.fromkeys(CHECKS, "pass"), {
        n: c.reason for n, c in checks.items() if c.verdict != "pass"
    }
    assert verdict_of(list(checks.values())) == "pass"
    assert checks["setpoints"].value == pytest.approx(1.0, abs=0.01)


def test_a_ground_station_that_falls_silent_fails_statustext_and_modes():
    checks = _by_name(_flight(gcs_lost_at=30.0))
    assert checks["statustext"].verdict == "fail" and "GCS Failsafe" in checks["statustext"].reason
    assert checks["statustext"].time_s == pytest.approx(30.0)
    assert checks["modes"].verdict == "fail" and "without a command" in checks["modes"].reason
    assert checks["setpoints"].verdict == "fail"  # the back-seat stopped too: the vehicle would hold still


def test_a_commanded_mode_change_is_not_a_fault():
    def commanded(ev, t, ms):
        if t == 30.0:  # MAV_CMD_DO_SET_MODE accepted, logged with that step's reports
            ev.on_mavlink(M.command_ack_encode(176, 0), 1_000_000_000 + 300 * 100_000_000)

    ev = _flight(gcs_lost_at=30.0, extra=commanded)
    assert _by_name(ev)["modes"].verdict == "pass"


@pytest.mark.parametrize("gap, verdict", [(2.0, "warn"), (5.0, "fail"), (0.5, "pass")])
def test_a_setpoint_stream_with_a_gap_is_held_against_guideds_timeout(gap, verdict):
    check = _by_name(_flight(setpoint_gap=(20.0, 20.0 + gap)))["setpoints"]
    assert check.verdict == verdict, check
    if verdict != "pass":
        assert check.value == pytest.approx(gap, abs=0.05) and check.time_s == pytest.approx(20.0, abs=0.05)


def test_a_pack_that_sags_fails():
    sag = _by_name(_flight(volts=lambda t: 12.6 if t < 30 else 10.0))["pack"]  # 21 % within a report
    assert sag.verdict == "fail" and "sagged" in sag.reason and sag.time_s == pytest.approx(30.0)
    step = _by_name(_flight(volts=lambda t: 12.6 if t < 30 else 11.8))["pack"]  # 6 %: a load step, as SITL's
    assert step.verdict == "pass", step
    flat = _by_name(_flight(volts=lambda t: 12.0 - 0.05 * t))["pack"]  # 3 cells down to 3.0 V each
    assert flat.verdict == "fail" and "3 cells" in flat.reason and flat.value < 3.3


def test_a_lost_position_segment_fails():
    gap = _by_name(_flight(position_gap=(25.0, 29.5)))["position"]
    assert gap.verdict == "fail" and gap.value == pytest.approx(4.5, abs=0.01)
    assert gap.time_s == pytest.approx(25.0, abs=0.01)
    const = _by_name(_flight(ekf=lambda t: (167 if 40 <= t < 45 else GOOD_FLAGS, 0.05, 0.04, 0.02)))["position"]
    assert const.verdict == "fail" and "constant-position" in const.reason and const.time_s == pytest.approx(40.0)


def test_estimator_variance_warns_then_fails_at_ardupilots_threshold():
    warn = _by_name(_flight(ekf=lambda t: (GOOD_FLAGS, 0.6 if t == 10 else 0.1, 0.04, 0.02)))["estimator"]
    assert warn.verdict == "warn" and warn.value == pytest.approx(0.6)
    fail = _by_name(_flight(ekf=lambda t: (GOOD_FLAGS, 0.1, 0.04, 0.9 if t > 50 else 0.02)))["estimator"]
    assert fail.verdict == "fail" and "compass" in fail.reason and fail.threshold == 0.8


def test_link_losses_name_their_source_and_a_missing_record_is_unknown():
    lossy = {**LOSSES, "link_lost": 300, "link_lost_by_source": {"vehicle": 290, "virtual-range": 10}}
    check = _by_name(_flight(), lossy)["link"]
    assert check.verdict == "fail" and "most from vehicle: 290" in check.reason
    assert _by_name(_flight(), {**LOSSES, "link_lost": 3})["link"].verdict == "warn"
    unknown = _by_name(_flight(), None)["link"]
    assert unknown.verdict == "unknown" and "rapt.losses" in unknown.reason


def test_depth_excursion_and_watchdog_intervention():
    def deep(ev, t, ms):
        if t == 12.0:
            ev.on_mavlink(M.global_position_int_encode(ms + 1, 0, 0, -6500, -6500, 0, 0, 0, 0), 0)

    assert _by_name(_flight(extra=deep))["depth"].verdict == "fail"
    ev = _flight()
    ev.on_event("watchdog", {"event": "intervention", "reason": "collision", "time_boot_ms": START_MS + 9000})
    check = _by_name(ev)["watchdog"]
    assert check.verdict == "warn" and "collision" in check.reason and check.time_s == pytest.approx(9.0)


def test_a_log_without_what_a_check_needs_says_unknown_and_the_rest_still_judge():
    ev = RunEvidence()
    ev.on_clock(START_MS)
    for k in range(50):
        ev.on_mavlink(M.global_position_int_encode(START_MS + k * 100, 0, 0, -2000, -2000, 0, 0, 0, 0), k)
    checks = _by_name(ev, None)
    assert checks["estimator"].verdict == "unknown" and "EKF_STATUS_REPORT" in checks["estimator"].reason
    assert checks["thrusters"].verdict == "unknown" and checks["pack"].verdict == "unknown"
    assert checks["position"].verdict == "pass"
    assert verdict_of(list(checks.values())) == "warn"
    line = summary_line([c.as_dict() for c in checks.values()])
    assert line.startswith("warn: ") and "estimator" in line


def test_a_gap_where_the_log_lost_a_chunk_is_unknown_not_a_fault():
    ev = _flight(position_gap=(25.0, 29.5))
    ev.lost_log_ns = [(1_000_000_000 + 260 * 100_000_000, 1_000_000_000 + 280 * 100_000_000)]  # 26-28 s
    check = _by_name(ev)["position"]
    assert check.verdict == "unknown" and "lost a chunk" in check.reason
    ev = _flight(position_gap=(25.0, 29.5))
    ev.lost_log_ns = [(1_000_000_000 + 400 * 100_000_000, 1_000_000_000 + 410 * 100_000_000)]  # elsewhere
    assert _by_name(ev)["position"].verdict == "fail"
