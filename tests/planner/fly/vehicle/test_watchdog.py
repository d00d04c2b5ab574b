"""The watchdog: its rules on explicit values, then the service on a real loopback bus (and a real vehicle link)."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from bridge import keys
from bridge.keys import WATCHDOG_SOURCE
from bridge.mavlink_bridge import MavlinkBridge
from bridge.setpoint import Setpoint
from planner.common.telemetry import VIRTUAL_BATTERY_ID, Pose
from planner.fly.run_bus import free_port
from planner.fly.vehicle.virtual_range import scenario_of
from planner.fly.vehicle.watchdog import (
    BATTERY,
    COLLISION,
    LINK_LOST,
    NOGO,
    OPERATIONAL_AREA,
    POSITION_LOST,
    STALE_COMMANDS,
    Watchdog,
    WatchdogRules,
    contact_distances,
)
from rapt.errors import InputError, LinkError
from sim.uuv.ardusub.frontseat import SURFACE, FrontSeat
from sim.uuv.mission import Rect, Triangle, Vehicle
from sim.uuv.scenario import make_scenarios
from tests.support.livebus import VEHICLE, FakeVehicle, Listener, bus
from tests.support.loopback import no_new_threads, wait_until
from tests.support.uuvworld import mission as small_mission

EXAMPLES = Path(__file__).resolve().parents[4] / "examples"
U = [0.5]
SAFE = (0.0, -300.0)  # open water in the small mission


@pytest.fixture(autouse=True)
def no_leftover_threads():
    with no_new_threads():
        yield


def _mission():
    """A 2x2 km box with a barrier, a small obstacle and a no-go area; 1000 Wh, full at the start."""
    return small_mission(
        barriers=(Rect("B", 0.0, 50.0, 200.0, 20.0),),
        obstacles=(Triangle("O", 60.0, -10.0, 20.0),),
        nogo=(Rect("NG", 300.0, 300.0, 100.0, 100.0),),
        vehicle=Vehicle(battery_wh=1000.0),
    )


def _pose(east, north, heading=0.0, t=1000):
    return Pose(t, east, north, 2.0, heading, t)


# --------------------------------------------------------------------------- the rules, pure
def test_each_rule_fires_with_its_reason_and_the_first_one_wins():
    m = _mission()
    scen = scenario_of(m, U)
    rules = WatchdogRules()

    def check(pose=None, battery=0.5, age=0.0, silence=0.0, pack=None):
        d = None if pose is None else contact_distances(scen, pose)
        return rules.check(scen, pose, d, battery, age, silence, pack)

    assert check(_pose(*SAFE)) is None
    hit = check(_pose(30.0, 45.0))  # inside the barrier
    assert hit is not None and hit.reason == COLLISION and "barrier B" in hit.detail
    touching = check(_pose(60.0, -10.0))  # the obstacle's centre
    assert touching is not None and touching.reason == COLLISION and "obstacle O" in touching.detail
    assert check(_pose(0.0, 39.5)) is None  # 0.5 m short of the barrier: not a collision
    nogo = check(_pose(310.0, 280.0))
    assert nogo is not None and nogo.reason == NOGO and "NG" in nogo.detail
    out = check(_pose(0.0, 1000.5))
    assert out is not None and out.reason == OPERATIONAL_AREA and "0.5 m outside" in out.detail
    assert check(_pose(0.0, 1000.0)) is None  # on the edge is still inside, as the scorer has it
    assert check(_pose(*SAFE), battery=0.001) is None
    empty = check(_pose(*SAFE), battery=0.0)  # the scenario's virtual gauge ran dry
    assert empty.reason == BATTERY and "scenario battery" in empty.detail
    assert check(_pose(*SAFE), pack=10.5) is None
    low = check(_pose(*SAFE), pack=10)  # the vehicle's real pack
    assert low.reason == BATTERY and "pack at 10%" in low.detail
    assert check(_pose(*SAFE), age=6.0) is None
    assert check(_pose(*SAFE), age=6.01).reason == STALE_COMMANDS
    assert check(_pose(*SAFE), silence=3.0) is None
    assert check(_pose(*SAFE), silence=3.01).reason == LINK_LOST
    # the first broken rule in REASONS order; no pose yet: only the rules that need none
    assert check(_pose(30.0, 45.0), battery=0.0, age=99.0, silence=99.0).reason == COLLISION
    assert check(None, battery=0.0, age=99.0).reason == BATTERY
    assert rules.check(scen, None, None, None, None, 99.0).reason == LINK_LOST


def test_a_lost_estimate_or_silent_position_reports_are_a_lost_position():
    scen = scenario_of(_mission(), U)
    rules = WatchdogRules()
    pose = _pose(*SAFE)

    def check(**kw):
        return rules.check(scen, pose, contact_distances(scen, pose), 0.5, 0.0, 0.0, None, **kw)

    assert check(position_age_s=3.0, ekf_flags=0x033F) is None  # ArduSub's flags once it uses GPS
    lost = check(ekf_flags=0x00A7)  # attitude and velocities only: no absolute horizontal position
    assert lost.reason == POSITION_LOST and "0x00a7" in lost.detail
    assert check(ekf_flags=0x033F | 128).reason == POSITION_LOST  # constant-position mode
    silent = check(position_age_s=3.5)  # ATTITUDE keeps coming, GLOBAL_POSITION_INT stopped
    assert silent.reason == POSITION_LOST and "3.5 s of vehicle time" in silent.detail
    # before the stale set-points the back-seat's silence would cause next
    assert rules.check(scen, pose, None, 0.5, 99.0, 0.0, position_age_s=9.0).reason == POSITION_LOST


def test_bad_thresholds_are_refused():
    with pytest.raises(InputError, match="critical_battery"):
        WatchdogRules(critical_battery=1.5)
    with pytest.raises(InputError, match="command_stale_s"):
        WatchdogRules(command_stale_s=0)
    with pytest.raises(InputError, match="pack_critical_percent"):
        WatchdogRules(pack_critical_percent=100)
    with pytest.raises(InputError, match=r"record_only: unknown reason\(s\) \['nowhere'\]"):
        WatchdogRules(record_only=frozenset({"nowhere"}))


def test_every_broken_rule_is_listed_in_order_for_record_only_reasons():
    m = _mission()
    scen = scenario_of(m, U)
    pose = _pose(310.0, 280.0)  # inside the no-go area
    rules = WatchdogRules(record_only=frozenset({NOGO}))
    broken = rules.broken(scen, pose, contact_distances(scen, pose), 0.5, 99.0, 0.0)
    assert [t.reason for t in broken] == [NOGO, STALE_COMMANDS]


# --------------------------------------------------------------------------- the service, on a bus
class FakeCommander:
    """The bridge's set_mode/linked: records modes; raises LinkError while unlinked."""

    def __init__(self, linked: bool = True):
        self.linked = linked
        self.modes: list[str] = []
        self._lock = threading.Lock()

    def set_mode(self, mode: str) -> int:
        if not self.linked:
            raise LinkError("set_mode: no autopilot heard within the last 2.0 s")
        with self._lock:
            self.modes.append(mode)
        return 0


class Rig:
    """A bus with a fake vehicle, a watchdog and listeners on what it publishes."""

    def __init__(self, session, *, commander=None, action="surface", rules=None, **kw):
        self.mission = _mission()
        self.session = session
        self.vehicle = FakeVehicle(session, self.mission)
        self.status = Listener(session, keys.status(VEHICLE, WATCHDOG_SOURCE))
        self.active = Listener(session, keys.active(VEHICLE))
        self.setpoints = Listener(session, keys.command(VEHICLE, WATCHDOG_SOURCE))
        self.commander = commander if commander is not None else FakeCommander()
        rules = rules or WatchdogRules(command_stale_s=60.0, link_lost_s=30.0)
        self.dog = Watchdog(
            session, VEHICLE, self.mission, U, self.commander, action=action, rules=rules, mode_retry_s=0.05, **kw
        ).start()

    def begin(self):
        self.dog.begin()
        wait_until(lambda: self.dog.armed, what="the watchdog armed")

    def events(self) -> list[dict]:
        return [json.loads(p) for p in self.status.payloads(keys.status(VEHICLE, WATCHDOG_SOURCE))]

    def wait_event(self, n: int = 1) -> list[dict]:
        wait_until(lambda: len(self.events()) >= n, what=f"{n} watchdog event(s)")
        return self.events()

    def sent(self) -> list[Setpoint]:
        return [Setpoint.from_json(p) for p in self.setpoints.payloads(keys.command(VEHICLE, WATCHDOG_SOURCE))]

    def close(self):
        self.dog.close()
        for part in (self.vehicle, self.status, self.active, self.setpoints):
            part.close()


@pytest.fixture
def rig():
    rigs: list[Rig] = []
    with bus() as session:

        def make(**kw) -> Rig:
            rigs.append(Rig(session, **kw))
            return rigs[-1]

        try:
            yield make
        finally:
            for r in rigs:
                r.close()


def _poses_then(r: Rig, scene: str) -> None:
    """Drive the vehicle into ``scene``'s broken rule."""
    v = r.vehicle
    if scene == COLLISION:
        v.pose(2000, 30.0, 45.0, 0.0)
    elif scene == NOGO:
        v.pose(2000, 310.0, 280.0, 0.0)
    elif scene == OPERATIONAL_AREA:
        v.pose(2000, 0.0, 1010.0, 0.0)
    elif scene == BATTERY:  # the virtual gauge says the scenario's charge is spent
        v.battery(int(1000 * 36), battery_id=VIRTUAL_BATTERY_ID)
    else:
        raise AssertionError(scene)


@pytest.mark.parametrize("reason", [COLLISION, NOGO, OPERATIONAL_AREA, BATTERY])
def test_a_broken_area_or_battery_rule_takes_control_and_surfaces(rig, reason):
    r = rig()
    r.vehicle.pose(1000, *SAFE, 0.3)
    wait_until(lambda: r.dog.stats["poses"] == 1, what="the first pose")
    r.begin()
    time.sleep(0.05)
    assert r.dog.intervention is None  # in open water, charged, heard from
    _poses_then(r, reason)
    (event,) = r.wait_event()
    assert r.dog.intervention == reason
    assert event["event"] == "intervention" and event["reason"] == reason and event["action"] == "surface"
    assert event["mode_result"] == 0 and r.commander.modes == ["SURFACE"]
    assert event["time_boot_ms"] == (1000 if reason == BATTERY else 2000) and event["detail"]
    assert r.active.payloads(keys.active(VEHICLE)) == [b"watchdog"]
    sp = r.sent()[0]
    assert (sp.vx, sp.vy, sp.vz) == (0.0, 0.0, -0.5)  # rising, keeping the heading it had
    assert sp.yaw == pytest.approx(0.0 if reason != BATTERY else 0.3, abs=1e-6)


def test_nothing_fires_before_begin_and_a_broken_rule_fires_at_once_after(rig):
    r = rig(rules=WatchdogRules(command_stale_s=0.5, link_lost_s=0.1))
    r.vehicle.pose(1000, 30.0, 45.0)  # already inside the barrier
    r.vehicle.pose(5000, 30.0, 45.0)  # and four vehicle seconds without a set-point
    wait_until(lambda: r.dog.stats["poses"] == 2, what="the poses")
    time.sleep(0.3)  # and silent for longer than link_lost_s
    assert r.dog.intervention is None and r.events() == [] and r.sent() == []
    r.begin()
    assert r.wait_event()[0]["reason"] == COLLISION


def test_stale_commands_count_by_the_vehicle_clock(rig):
    r = rig(rules=WatchdogRules(command_stale_s=1.0, link_lost_s=30.0))
    commands = r.session.declare_publisher(keys.command(VEHICLE, "autonomy"))
    r.vehicle.pose(1000, *SAFE)
    r.begin()
    commands.put(Setpoint(1.0, 0.0, 0.5, 0.0, 1000).to_json())
    wait_until(lambda: r.dog.stats["commands_in"] == 1, what="the set-point")
    r.vehicle.pose(1900, *SAFE)
    wait_until(lambda: r.dog.stats["poses"] == 2, what="a pose 0.9 s later")
    time.sleep(0.3)  # wall time alone does not make commands stale
    assert r.dog.intervention is None
    r.vehicle.pose(2100, *SAFE)  # 1.1 vehicle seconds after the set-point
    event = r.wait_event()[0]
    commands.undeclare()
    assert event["reason"] == STALE_COMMANDS and event["time_boot_ms"] == 2100
    assert "1.1 s" in event["detail"]


def test_a_lost_link_surfaces_as_soon_as_the_vehicle_hears_again(rig):
    commander = FakeCommander(linked=False)
    r = rig(commander=commander, rules=WatchdogRules(command_stale_s=60.0, link_lost_s=0.2))
    started = time.monotonic()
    r.vehicle.pose(1000, *SAFE)
    r.begin()
    (event,) = r.wait_event()
    assert time.monotonic() - started >= 0.2  # silent since the pose
    assert event["reason"] == LINK_LOST and event["mode_result"] is None and "no autopilot" in event["mode_error"]
    time.sleep(0.2)
    assert commander.modes == [] and r.dog.stats["mode_attempts"] >= 2  # retried while the link was down
    commander.linked = True
    events = r.wait_event(2)
    assert events[1]["event"] == "mode" and events[1]["mode_result"] == 0 and commander.modes == ["SURFACE"]


def test_hold_keeps_refreshing_zero_velocity_and_commands_no_mode(rig):
    r = rig(action="hold", setpoint_hz=10.0, commander=FakeCommander())
    r.vehicle.pose(1000, *SAFE, 1.0)
    r.begin()
    r.vehicle.pose(2000, 0.0, 1010.0, 1.0)
    (event,) = r.wait_event()
    assert event["reason"] == OPERATIONAL_AREA and event["action"] == "hold" and event["mode_result"] is None
    wait_until(lambda: len(r.sent()) >= 4, what="refreshed set-points")
    assert {(sp.vx, sp.vy, sp.vz) for sp in r.sent()} == {(0.0, 0.0, 0.0)}
    assert [sp.yaw for sp in r.sent()] == pytest.approx([1.0] * len(r.sent()), abs=1e-6)
    assert r.commander.modes == []
    # the count goes up once a set-point is out, so the vehicle may hear the fourth before the count shows it
    wait_until(lambda: r.dog.stats["setpoints_out"] >= 4, what="the watchdog's count of its set-points")


def test_the_watched_source_cannot_be_the_watchdog_and_surface_needs_a_commander():
    m = _mission()
    with bus() as session:
        with pytest.raises(InputError, match="watched"):
            Watchdog(session, VEHICLE, m, U, FakeCommander(), watched=WATCHDOG_SOURCE)
        with pytest.raises(InputError, match="commander"):
            Watchdog(session, VEHICLE, m, U, None)
        with pytest.raises(InputError, match="action"):
            Watchdog(session, VEHICLE, m, U, FakeCommander(), action="dive")


# --------------------------------------------------------------------------- a real vehicle link
@pytest.mark.integration
def test_on_a_real_link_the_watchdog_puts_the_vehicle_in_surface_mode():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(3).random((20, m.dim))
    u = X[np.flatnonzero(make_scenarios(m, X).valid)[0]]
    port = free_port()
    fs = FrontSeat(m, u, f"udpin:127.0.0.1:{port}", lockstep=False, speedup=10.0)
    fs_thread = threading.Thread(target=fs.serve, name="frontseat", daemon=True)
    fs_thread.start()
    try:
        with bus() as session:
            status = Listener(session, keys.status(VEHICLE, WATCHDOG_SOURCE))
            with MavlinkBridge(f"udpout:127.0.0.1:{port}", session, vehicle=VEHICLE, allow_commands=True) as bridge:
                wait_until(lambda: bridge.target is not None, what="the vehicle's heartbeat")
                assert bridge.set_mode("GUIDED") == 0 and bridge.arm(True) == 0
                rules = WatchdogRules(command_stale_s=2.0, link_lost_s=30.0)
                with Watchdog(session, VEHICLE, m, u, bridge, rules=rules) as dog:
                    dog.begin()  # and no back-seat ever commands
                    wait_until(lambda: fs.mode == SURFACE, timeout=10, what="SURFACE on the vehicle")
                    wait_until(lambda: status.items(), what="the event")
                    assert dog.intervention == STALE_COMMANDS
                    wait_until(
                        lambda: bridge.active == WATCHDOG_SOURCE, what="the bridge taking the watchdog's commands"
                    )
            event = json.loads(status.items()[0][1])
            status.close()
    finally:
        fs.stop()
        fs_thread.join(timeout=5)
        fs.close()
    assert event["reason"] == STALE_COMMANDS and event["mode_result"] == 0
    assert event["time_boot_ms"] >= 2000 and math.isfinite(event["time_boot_ms"])


def test_a_record_only_reason_is_published_once_and_the_run_goes_on(rig):
    """A virtual no-go area the plan expects the vehicle to enter: recorded, not taken over."""
    r = rig(rules=WatchdogRules(record_only=frozenset({NOGO}), link_lost_s=30.0))
    r.vehicle.pose(1000, *SAFE, 0.3)
    wait_until(lambda: r.dog.stats["poses"] == 1, what="the first pose")
    r.begin()
    r.vehicle.pose(2000, 310.0, 280.0, 0.0)
    r.vehicle.pose(2100, 311.0, 280.0, 0.0)
    (event,) = r.wait_event()
    time.sleep(0.1)
    assert event["event"] == "violation" and event["reason"] == NOGO and len(r.events()) == 1
    assert r.dog.intervention is None and r.dog.violations.keys() == {NOGO}
    assert r.active.payloads(keys.active(VEHICLE)) == [] and r.sent() == [] and r.commander.modes == []
    r.vehicle.pose(2200, 0.0, 1010.0, 0.0)  # then out of the operational area: that one takes over
    assert r.wait_event(2)[1]["reason"] == OPERATIONAL_AREA and r.dog.intervention == OPERATIONAL_AREA
