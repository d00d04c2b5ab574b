"""The onboard guard on ArduSub's firmware: installed by bring-up, it surfaces a vehicle whose run was killed;
a vehicle that cannot take it is refused in one line, and the run then proceeds only with --no-guard."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")

from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary  # noqa: E402
from planner.fly.flight import flight_from_plan  # noqa: E402
from planner.fly.vehicle.guard import GuardOptions  # noqa: E402
from planner.fly.vehicle.run import run_vehicle  # noqa: E402
from rapt.errors import RefusedError  # noqa: E402
from sim.uuv.missionfile import load_mission  # noqa: E402
from tests.support.firmware_run import Monitor, kill_mid_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[4]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
LAUNCH = launch_point(load_mission(ROOT / "examples" / "range2017.toml"))
SURFACE = 9
SPEEDUP = 10.0

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")
pytestmark = [needs_firmware, pytest.mark.sitl, pytest.mark.integration, pytest.mark.slow]  # 9 s and more each


def test_a_run_killed_mid_scenario_is_surfaced_by_the_guard_within_its_timeout(tmp_path):
    """kill -9 of ``rapt-plan run --mavlink`` 20 vehicle seconds into pair2b: nothing of ours is left to
    command the vehicle, and the guard installed at bring-up switches it to SURFACE within its timeout
    (10 vehicle seconds) + 3, saying why."""
    with ArduSubSitl(LAUNCH, speedup=SPEEDUP) as sitl:
        monitor = Monitor(sitl.port + 2)
        try:
            log = str(tmp_path / "killed.mcap")
            run = kill_mid_scenario(sitl.connection, monitor, PLAN, "pair2b", 20.0, "--log", log)
            assert any(" guard " in line and "running" in line for line in run.lines), run.lines
            assert run.mode_at_kill == 4, monitor.modes[-3:]  # flying the scenario in GUIDED
            killed_ms = run.killed_ms
            surfaced_ms = monitor.wait(
                lambda: next((t for t, mode in monitor.modes if t >= killed_ms and mode == SURFACE), None),
                30,
                "SURFACE after the kill",
            )
            said = monitor.wait(
                lambda: next(
                    (text for _, text in monitor.texts if text.startswith("RAPT guard: back-seat silent")), None
                ),
                10,
                "the guard's STATUSTEXT",
            )
        finally:
            monitor.close()
    assert run.returncode == -signal.SIGKILL
    # its last beat came up to one beat (2 vehicle s here) before the kill: SURFACE within the timeout + 3 of it
    assert 0 < surfaced_ms - killed_ms <= 13_000, (killed_ms, surfaced_ms)
    assert "SURFACE" in said


def test_a_vehicle_that_cannot_take_the_guard_is_refused_in_one_line_and_flies_with_no_guard():
    """Scripting off: refused naming --guard-reboot; a script path the vehicle cannot write: refused naming
    it, before any reboot; --no-guard (guard None): flown, and the timeline says it flew unguarded."""
    flight = flight_from_plan(PLAN, "pair2b")
    with ArduSubSitl(LAUNCH, speedup=SPEEDUP, parameters={"SCR_ENABLE": 0}) as sitl:
        with pytest.raises(RefusedError) as off:
            run_vehicle(flight, sitl.connection, timeout_s=5.0)
        line = str(off.value)
        assert "\n" not in line and "scripting is off" in line and "--guard-reboot" in line and "--no-guard" in line
        with pytest.raises(RefusedError) as unwritable:
            # consent to a reboot given, but the script cannot be written: refused before any reboot
            bad = GuardOptions(path="no/such/dir/rapt_guard.lua", reboot=True)
            run_vehicle(flight, sitl.connection, timeout_s=5.0, guard=bad)
        line = str(unwritable.value)
        assert "\n" not in line and "refused to write 'no/such/dir/rapt_guard.lua'" in line and "--no-guard" in line
        steps: list = []
        result = run_vehicle(flight, sitl.connection, timeout_s=3.0, guard=None, say=steps.append)
    assert result.ended.startswith("wall-time limit")
    [guard] = [s for s in steps if s.name == "guard"]
    assert guard.status == "note" and "--no-guard" in guard.detail and "nothing surfaces the vehicle" in guard.detail


def test_guard_reboot_turns_scripting_on_reboots_the_disarmed_vehicle_and_installs_the_guard():
    """With the operator's consent (--guard-reboot) a vehicle with scripting off gets SCR_ENABLE 1 and one reboot,
    comes back with it kept, runs the guard and flies; the timeline says it rebooted."""
    flight = flight_from_plan(PLAN, "pair2b")
    with ArduSubSitl(LAUNCH, speedup=SPEEDUP, parameters={"SCR_ENABLE": 0}) as sitl:
        steps: list = []
        result = run_vehicle(flight, sitl.connection, timeout_s=3.0, guard=GuardOptions(reboot=True), say=steps.append)
        assert result.ended.startswith("wall-time limit")
        guard = [s for s in steps if s.name == "guard"]
        assert any(s.status == "note" and "rebooting the vehicle (--guard-reboot)" in s.detail for s in guard)
        assert guard[-1].status == "ok" and "running from" in guard[-1].detail
        # the vehicle keeps it: the next bring-up (back to the start first) needs no reboot
        steps.clear()
        run_vehicle(flight, sitl.connection, timeout_s=3.0, transit=True, say=steps.append)
        guard = [s for s in steps if s.name == "guard"]
        assert [s.status for s in guard] == ["ok"] and not any("reboot" in s.detail for s in guard)
