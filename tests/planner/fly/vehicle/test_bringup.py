"""Bring-up like a careful operator: each step's success, and each step's failure in one line, on loopback MAVLink."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import socket
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner.fly.flight import Flight, flight_from_plan  # noqa: E402
from planner.fly.vehicle.bringup import BringUpTimeouts  # noqa: E402
from planner.fly.vehicle.run import run_vehicle  # noqa: E402
from rapt.errors import InputError, LinkTimeoutError, RefusedError, RunError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.missionfile import load_mission  # noqa: E402
from tests.support.fake_ardusub import Behaviour, FakeArduSub  # noqa: E402
from tests.support.loopback import free_port, no_new_threads  # noqa: E402

M = mavutil.mavlink
ROOT = Path(__file__).resolve().parents[4]
FAST = BringUpTimeouts(heartbeat=5, streams=2, estimate=1.5, mission=3, guided=1.5, arm=1.5, depth=5, surface=5)
STEPS = ["heartbeat", "streams", "estimate", "area", "start", "guard", "mission", "guided", "arm", "depth", "clock"]


@pytest.fixture(scope="module")
def flight():
    return flight_from_plan(ROOT / "field_plans" / "range2017" / "plan.json", "pair2b")


@contextlib.contextmanager
def fake(route, **behaviour):
    port = free_port(socket.SOCK_DGRAM)
    with no_new_threads():
        vehicle = FakeArduSub(f"udpout:127.0.0.1:{port}", route, Behaviour(**behaviour))
        try:
            yield f"udpin:127.0.0.1:{port}", vehicle
        finally:
            vehicle.close()


def _fly(flight, connection, steps: list, **kw):
    return run_vehicle(flight, connection, timeout_s=0.5, say=steps.append, **{"guard": None, "timeouts": FAST, **kw})


def _commanded(vehicle) -> list[str]:
    """What the vehicle was told beyond our heartbeat, the message rates and parameter reads (they change nothing)."""
    out = []
    for m in vehicle.received:
        kind = m.get_type()
        if kind == "COMMAND_LONG" and m.command == M.MAV_CMD_SET_MESSAGE_INTERVAL or kind == "HEARTBEAT":
            continue
        if kind == "PARAM_REQUEST_READ":
            continue
        out.append(kind if kind != "COMMAND_LONG" else f"COMMAND_LONG {m.command}")
    return out


def test_every_step_in_order_and_set_points_only_in_guided(flight):
    steps: list = []
    with fake(flight.mission) as (conn, vehicle):
        result = _fly(flight, conn, steps)
    assert [s.name for s in steps][: len(STEPS)] == STEPS
    # the fake vehicle has no scripting: flown with --no-guard, the timeline says so and the rest is ok
    assert [(s.status, "--no-guard" in s.detail) for s in steps if s.name == "guard"] == [("note", True)]
    assert all(s.status == "ok" for s in steps if s.name != "guard")
    assert result.timeline[-1].name == "recover" and "disarmed" in result.timeline[-1].detail
    told = _commanded(vehicle)
    guided = told.index(f"COMMAND_LONG {M.MAV_CMD_DO_SET_MODE}")
    assert told.index("MISSION_COUNT") < guided  # the mission is uploaded before anything moves
    assert "SET_POSITION_TARGET_LOCAL_NED" not in told[:guided]  # nothing is commanded outside GUIDED
    # surfaced, then disarmed (SURFACE, or ALT_HOLD if it reached the top armed: ArduSub's hand-over)
    assert vehicle.mode in (9, 2) and vehicle.depth == 0.0 and not vehicle.armed


@pytest.mark.parametrize(
    ("behaviour", "error", "line", "last_step"),
    [
        (
            {"intervals": False, "stream": False},
            LinkTimeoutError,
            "bring-up streams: no GLOBAL_POSITION_INT",
            "streams",
        ),
        ({"ekf_flags": 0x00A7}, LinkTimeoutError, "bring-up estimate: no position estimate within 1.5 s", "estimate"),
        ({"mission": M.MAV_MISSION_NO_SPACE}, RefusedError, "refused the upload (MAV_MISSION_NO_SPACE)", "mission"),
        ({"mission": None}, LinkTimeoutError, "bring-up mission:", "mission"),
        ({"guided": M.MAV_RESULT_FAILED}, RefusedError, "bring-up guided: refused", "guided"),
        ({"arm": M.MAV_RESULT_DENIED}, RefusedError, "bring-up arm: refused", "arm"),
        ({"dives": False}, LinkTimeoutError, "bring-up depth: not at 2 m within 5 s", "depth"),
    ],
)
def test_a_step_that_fails_stops_the_run_with_one_line(flight, behaviour, error, line, last_step):
    steps: list = []
    with fake(flight.mission, **behaviour) as (conn, vehicle):
        with pytest.raises(error) as info:
            _fly(flight, conn, steps)
    assert line in str(info.value) and "\n" not in str(info.value)
    failed = [s for s in steps if s.status == "failed"]
    assert [s.name for s in failed] == [last_step]
    told = _commanded(vehicle)
    if last_step in ("streams", "estimate", "mission", "guided"):
        assert "COMMAND_LONG 400" not in told  # never armed
        assert "SET_POSITION_TARGET_LOCAL_NED" not in told
    if last_step == "streams":
        assert "REQUEST_DATA_STREAM" in told  # the fallback was tried
    if last_step == "depth":  # armed by then: it is brought up and disarmed before the error is raised
        assert vehicle.mode in (9, 2) and not vehicle.armed and steps[-1].name == "recover"


def test_the_thrusters_pwm_limits_are_asked_for_so_the_log_carries_them(flight):
    steps: list = []
    with fake(flight.mission) as (conn, vehicle):
        _fly(flight, conn, steps)
    asked = [m.param_id for m in vehicle.received if m.get_type() == "PARAM_REQUEST_READ"]
    assert asked == ["MOT_PWM_MIN", "MOT_PWM_MAX"]


def test_streams_fall_back_to_request_data_stream(flight):
    steps: list = []
    with fake(flight.mission, intervals=False) as (conn, vehicle):
        _fly(flight, conn, steps)
    fallback = [s for s in steps if s.status == "fallback"]
    assert fallback and fallback[0].name == "streams" and "REQUEST_DATA_STREAM" in fallback[0].detail
    assert "REQUEST_DATA_STREAM" in vehicle.kinds()


def test_a_vehicle_outside_the_scenarios_area_is_refused_before_anything_is_commanded(flight):
    """range2017's launch point is south of imitation7's operational area (y -500..500)."""
    mission = load_mission(ROOT / "examples" / "imitation7.toml")
    other = Flight(mission, flight.u[: mission.dim] * 0 + 0.5, "centre", "examples/imitation7.toml")
    steps: list = []
    with fake(flight.mission) as (conn, vehicle):
        with pytest.raises(InputError, match=r"--scenario: the vehicle is at \(-480, -520\) m, outside mission"):
            _fly(other, conn, steps)
    assert steps[-1].name == "area" and _commanded(vehicle) == []


def test_arming_is_re_checked_in_guided_and_never_sent_in_another_mode(flight):
    """The first arm is refused and the vehicle drops to MANUAL meanwhile (a pilot, a failsafe): the
    bring-up must not ask again in MANUAL.  It stops in one line, the vehicle never armed."""
    steps: list = []
    with fake(flight.mission, arm_denials=1, denial_switches_to=19) as (conn, vehicle):
        with pytest.raises(RunError) as info:
            _fly(flight, conn, steps)
    assert str(info.value) == "bring-up arm: the vehicle left GUIDED before it was armed (now MANUAL)"
    assert vehicle.arm_modes == [4] and not vehicle.armed  # one request, in GUIDED; none in MANUAL
    assert [s.name for s in steps if s.status == "failed"] == ["arm"]
    assert "SET_POSITION_TARGET_LOCAL_NED" not in _commanded(vehicle)


def test_the_bridge_arm_option_takes_guided_back_before_arming_again(flight):
    """``rapt-plan bridge --arm`` (arm_when_heard): after a refused arm that left the vehicle in MANUAL
    it asks for GUIDED again and arms only once the heartbeat shows it."""
    from bridge.mavlink_bridge import MavlinkBridge
    from bridge.session import open_session
    from planner.fly.lifecycle import arm_when_heard

    with fake(flight.mission, arm_denials=2, denial_switches_to=19) as (conn, vehicle):
        session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
        try:
            with MavlinkBridge(conn, session, vehicle="uuv1", allow_commands=True) as link:
                assert arm_when_heard(link, timeout_s=10.0, guided_s=10.0)
                wait_for_armed = [vehicle.armed, vehicle.mode]
                assert link.arm(False) == M.MAV_RESULT_ACCEPTED
        finally:
            session.close()
    assert vehicle.arm_modes == [4, 4, 4]  # every request in GUIDED: two refused, the third accepted
    assert wait_for_armed == [True, 4]


@pytest.mark.parametrize(
    ("failsafe_mode", "ended"),
    [
        (None, "vehicle: disarmed itself (a failsafe, or disarmed by someone else)"),
        (19, "vehicle: left GUIDED (now MANUAL: a failsafe, or a pilot took it)"),
    ],
)
def test_a_vehicle_that_ends_the_run_itself_is_left_alone(flight, failsafe_mode, ended):
    """Mid-run, the vehicle's failsafe disarms it or a pilot takes it to MANUAL: the run ends with that
    reason in one line and in the timeline, and nothing more is commanded (no SURFACE, no disarm)."""
    steps: list = []
    with fake(flight.mission, failsafe_after_s=4.0, failsafe_mode=failsafe_mode) as (conn, vehicle):
        result = run_vehicle(flight, conn, timeouts=FAST, timeout_s=15.0, say=steps.append, guard=None)
        after = vehicle.received[vehicle.failsafe_at :] if vehicle.failsafe_at is not None else None
    assert after is not None and result.ended == ended and result.watchdog == ""
    assert [s.name for s in steps][: len(STEPS)] == STEPS  # it was flying: every step went through
    assert steps[-1].name == "recover" and steps[-1].detail == f"nothing commanded: {ended}"
    commands = [m for m in after if m.get_type() == "COMMAND_LONG" and m.command != M.MAV_CMD_SET_MESSAGE_INTERVAL]
    assert commands == []  # neither SURFACE nor a disarm for a vehicle someone else now has
    assert vehicle.armed == (failsafe_mode is not None)  # as the failsafe or the pilot left it


def test_a_pilot_who_takes_the_vehicle_during_the_dive_is_not_fought(flight):
    """The bring-up fails in one line, and the vehicle, now in MANUAL, is neither surfaced nor disarmed."""
    steps: list = []
    with fake(flight.mission, failsafe_after_s=0.2, failsafe_mode=19, dives=False) as (conn, vehicle):
        with pytest.raises(RunError, match=r"^bring-up depth: the vehicle left GUIDED \(now MANUAL\)$"):
            _fly(flight, conn, steps)
        after = vehicle.received[vehicle.failsafe_at or 0 :]
    assert vehicle.failsafe_at is not None and vehicle.armed and vehicle.mode == 19
    assert not [m for m in after if m.get_type() == "COMMAND_LONG" and m.command != M.MAV_CMD_SET_MESSAGE_INTERVAL]
    assert steps[-1].name == "recover" and steps[-1].detail.startswith("nothing commanded: vehicle: left GUIDED")


def test_an_earlier_runs_vehicle_handed_to_alt_hold_at_the_top_counts_as_surfaced(flight):
    """A killed run left the vehicle armed in GUIDED at 3 m.  SURFACE brings it up and, at the top, ArduSub
    switches itself to ALT_HOLD (SURFACE_COMPLETE) while the depth sensor, 0.36 m under the waterline,
    still reads deeper than "surfaced" and has not yet held still: that is the surface, not a pilot."""
    steps: list = []

    def operator(step):  # this run's own steps are the other tests': stop once the earlier run is dealt with
        steps.append(step)
        if step.name == "estimate":
            raise KeyboardInterrupt

    with fake(flight.mission, earlier_run_depth_m=3.0, sensor_below_m=0.36) as (conn, vehicle):
        with pytest.raises(KeyboardInterrupt):
            run_vehicle(flight, conn, timeouts=FAST, timeout_s=0.5, say=operator, guard=None)
        told = _commanded(vehicle)
    assert [s.name for s in steps] == ["heartbeat", "streams", "previous", "estimate"]
    assert steps[2].status == "ok" and "armed in GUIDED from an earlier run" in steps[2].detail
    assert vehicle.mode == 2 and vehicle.depth == 0.0 and not vehicle.armed  # handed to ALT_HOLD, then disarmed
    surface, disarm = f"COMMAND_LONG {M.MAV_CMD_DO_SET_MODE}", f"COMMAND_LONG {M.MAV_CMD_COMPONENT_ARM_DISARM}"
    assert told == [surface, disarm]  # nothing else: SURFACE, then the disarm


def test_an_earlier_runs_vehicle_put_in_alt_hold_at_depth_is_not_fought(flight):
    """ALT_HOLD deep down is a failsafe's hold or a pilot's: the bring-up stops in one line and never disarms."""
    steps: list = []
    behaviour = {"earlier_run_depth_m": 20.0, "failsafe_after_s": 0.5, "failsafe_mode": 2}
    with fake(flight.mission, **behaviour) as (conn, vehicle):
        with pytest.raises(RefusedError, match=r"^bring-up previous: while surfacing, the vehicle went to ALT_HOLD$"):
            _fly(flight, conn, steps)
        told = _commanded(vehicle)
    assert vehicle.armed and vehicle.mode == 2 and vehicle.depth > 5.0
    assert f"COMMAND_LONG {M.MAV_CMD_COMPONENT_ARM_DISARM}" not in told


def test_a_vehicle_already_armed_in_alt_hold_is_refused_before_anything_is_commanded(flight):
    steps: list = []
    with fake(flight.mission, earlier_run_depth_m=0.0, earlier_run_mode=2) as (conn, vehicle):
        with pytest.raises(RefusedError) as refused:
            _fly(flight, conn, steps)
        told = _commanded(vehicle)
    line = str(refused.value)
    assert "already armed in ALT_HOLD (a pilot's hold, or an earlier run's vehicle that SURFACE" in line
    assert line.endswith("disarm it before rapt-plan run") and "\n" not in line
    assert [s.name for s in steps if s.status == "failed"] == ["heartbeat"]
    assert not [k for k in told if k.startswith("COMMAND_LONG")] and vehicle.armed and vehicle.mode == 2


def _moved_off_start(vehicle, mission, east_m: float) -> None:
    """The fake vehicle, disarmed at the surface, ``east_m`` east of the launch point (as a current carries it)."""
    lx, ly = mission.launch
    vehicle.lat, vehicle.lon = LocalFrame(mission.origin_lat, mission.origin_lon).to_latlon(lx + east_m, ly)


def test_a_disarmed_vehicle_that_drifted_off_its_start_is_flown_back_by_default(flight, monkeypatch):
    # the scripted vehicle does not fly the transit leg: the decision is the test, so the leg's wait is cut short
    monkeypatch.setattr("planner.fly.vehicle.bringup.TRANSIT_SLOWEST_MPS", 1e3)
    steps: list = []
    with fake(flight.mission) as (conn, vehicle):
        _moved_off_start(vehicle, flight.mission, 20.0)
        with contextlib.suppress(RunError, LinkTimeoutError, RefusedError):
            _fly(flight, conn, steps, timeouts=dataclasses.replace(FAST, transit=0.5))
    [start] = [s for s in steps if s.name == "start"]
    assert start.status == "note" and "drifted while disarmed" in start.detail and "transit leg" in start.detail
    names = [s.name for s in steps]
    assert names.index("start") < names.index("arm"), names  # not refused: bring-up went on to arm and dive


@pytest.mark.parametrize(("east_m", "drift_m"), [(60.0, 50.0), (20.0, 0.0)])
def test_a_vehicle_beyond_the_drift_allowance_is_refused_before_anything_is_commanded(flight, east_m, drift_m):
    steps: list = []
    with fake(flight.mission) as (conn, vehicle):
        _moved_off_start(vehicle, flight.mission, east_m)
        with pytest.raises(InputError) as refused:
            _fly(flight, conn, steps, drift_transit_m=drift_m)
    line = str(refused.value)
    assert "\n" not in line and line.startswith(f"--start-tolerance: the vehicle is {east_m:.0f} m from")
    assert f"beyond the {drift_m:g} m of drift" in line and "--transit" in line
    assert steps[-1].name == "start" and _commanded(vehicle) == []
