"""Real ground-station clients against the simulated front-seat over loopback TCP: pymavlink, MAVProxy, MAVSDK.

Each does what its users do on a range day, and each runs the same sequence against ArduSub
SITL 4.7.0-dev (flavour ``sitl``, marked ``sitl`` and ``slow``, 11-13 s each, skipped where ``ARDUSUB_SITL``
is not set), so what passes on the simulated front-seat is what the real firmware lets these
clients do.  The bare front-seat is the vehicle a ground station meets; the lock-step one is
checked where its clock does not matter (connect, parameters, mode, arming, missions).

MAVSDK 4 is the native binding (no mavsdk_server process): a ``Mavsdk`` object in this
process connects with ``tcpout://127.0.0.1:P``.  It has no ArduSub flight modes: its
Offboard.start() fails for a submarine ("Cannot translate flight mode to ArduPilot mode")
on SITL as here, so the test sets GUIDED with a COMMAND_LONG (MavlinkDirect), after which
MAVSDK reports OFFBOARD and its Offboard velocity set-points (SET_POSITION_TARGET_LOCAL_NED)
move the vehicle, as on SITL.
"""

from __future__ import annotations

import json
import math
import os
import queue
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil, mavwp  # noqa: E402

from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from sim.uuv.missionfile import load_mission  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402
from tests.support.uuvworld import mission  # noqa: E402

pytestmark = [pytest.mark.integration]

mav = mavutil.mavlink
ROOT = Path(__file__).resolve().parents[4]
#: A WPL file the planner wrote for range2017 (home, 8 waypoints and loiters at 2 m depth).
WPL = ROOT / "field_plans" / "range2017" / "pair1a.waypoints"
GUIDED = 4
#: range2017's launch point, SITL's home.
SITL_HOME = launch_point(load_mission(ROOT / "examples" / "range2017.toml"))
SITL = pytest.param(
    "sitl",
    marks=[
        pytest.mark.sitl,
        pytest.mark.slow,
        pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary"),
    ],
)


class Served:
    """The vehicle a client connects to on TCP ``port``: a front-seat (bare or lock-step) served in a
    thread, or ArduSub SITL (``sitl``); stopped and closed on exit.

    ``speedup`` <= 4 keeps ArduSub's GCS failsafe (5 s of vehicle time without a heartbeat from
    system 255) quiet for clients that send their heartbeat once a wall second, as MAVProxy does.
    """

    def __init__(self, flavour: str, speedup: float = 2.0):
        self.flavour, self.speedup = flavour, speedup
        self.fs: FrontSeat | None = None
        self.sitl: ArduSubSitl | None = None
        if flavour == "sitl":
            self.sitl = ArduSubSitl(home=SITL_HOME, speedup=speedup)
            return
        self.port = free_port()
        bare = flavour == "bare"
        self.fs = FrontSeat(
            mission(), [0.5], f"tcpin:127.0.0.1:{self.port}", bare=bare, lockstep=not bare, speedup=speedup,
            ekf_ready_s=0.0,
        )  # fmt: skip
        self.thread = threading.Thread(target=self.fs.serve, name=f"frontseat-{flavour}", daemon=True)

    def __enter__(self) -> Served:
        if self.sitl is not None:
            self.port = self.sitl.start().port
        else:
            self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.sitl is not None:
            self.sitl.stop()
            return
        assert self.fs is not None
        self.fs.stop()
        self.thread.join(timeout=5)
        assert not self.thread.is_alive()
        self.fs.close()

    @property
    def home(self) -> tuple[float, float]:
        if self.fs is None:
            return SITL_HOME[0], SITL_HOME[1]
        return self.fs.frame.to_latlon(float(self.fs.world.state.x[0]), float(self.fs.world.state.y[0]))

    def param_count_ok(self, count: int) -> bool:
        """Ours lists its table; SITL about 1,386 (the count grows by a few as drivers start)."""
        return count == len(self.fs.params) if self.fs is not None else 1300 < count < 1500

    @property
    def guided_wait_s(self) -> float:
        """How long GUIDED may be refused after connecting: SITL's EKF uses GPS ~40 vehicle s after boot."""
        return 60.0 / self.speedup if self.sitl is not None else 2.0


def fixed(position):
    """``position`` if it has a latitude (MAVSDK gives NaN, ArduSub 0 before its GPS is found)."""
    return position if math.isfinite(position.latitude_deg) and position.latitude_deg != 0 else None


def recv(c, kind, timeout: float = 3.0):
    msg = c.recv_match(type=kind, blocking=True, timeout=timeout)
    assert msg is not None, f"no {kind} within {timeout} s"
    return msg


# --------------------------------------------------------------------------------------------- pymavlink
@pytest.mark.parametrize("flavour", ["bare", "lockstep", SITL])
def test_pymavlink_connects_fetches_parameters_flies_guided_and_round_trips_a_mission(flavour):
    with Served(flavour, speedup=4.0 if flavour == "sitl" else 10.0) as v:
        c = mavutil.mavlink_connection(
            f"tcp:127.0.0.1:{v.port}", source_system=255, source_component=190, dialect="ardupilotmega"
        )
        try:
            hb = c.wait_heartbeat(timeout=5)
            assert hb is not None and (hb.type, hb.autopilot) == (
                mav.MAV_TYPE_SUBMARINE,
                mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
            )

            # every parameter, indices 0..count-1 once each
            c.param_fetch_all()
            seen: dict[int, str] = {}
            count = None
            while count is None or len(seen) < count:
                p = recv(c, "PARAM_VALUE")
                if p.param_index == 65535:
                    continue  # a value that changed on its own (ArduSub reports those too), not in the list
                count = p.param_count
                seen[p.param_index] = p.param_id
            assert set(seen) == set(range(count)) and v.param_count_ok(count)
            assert {"FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "WPNAV_SPEED"} <= set(c.params)

            deadline = time.monotonic() + v.guided_wait_s
            while True:  # ArduSub refuses GUIDED until its position estimate is ready
                c.set_mode("GUIDED")  # MAV_CMD_DO_SET_MODE with ArduSub's custom mode 4
                ack = recv(c, "COMMAND_ACK")
                if ack.result == mav.MAV_RESULT_ACCEPTED or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert (ack.command, ack.result) == (mav.MAV_CMD_DO_SET_MODE, mav.MAV_RESULT_ACCEPTED)
            c.arducopter_arm()
            assert recv(c, "COMMAND_ACK").result == mav.MAV_RESULT_ACCEPTED
            wait_until(
                lambda: c.recv_match(type="HEARTBEAT", blocking=True, timeout=1) and c.motors_armed(), 5, "armed"
            )
            assert c.flightmode == "GUIDED"

            # a planner WPL file through mavwp, up and back down
            wp = mavwp.MAVWPLoader(target_system=1, target_component=1)
            assert wp.load(str(WPL)) == 9
            c.waypoint_count_send(wp.count())
            while True:
                m = recv(c, ["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"])
                if m.get_type() == "MISSION_ACK":
                    break
                c.mav.send(wp.wp(m.seq))
            assert m.type == mav.MAV_MISSION_ACCEPTED
            c.waypoint_request_list_send()
            assert recv(c, "MISSION_COUNT").count == 9
            for seq in range(1, 9):
                c.mav.mission_request_int_send(1, 1, seq)
                got, sent = recv(c, "MISSION_ITEM_INT"), wp.wp(seq)
                assert (got.seq, got.command, got.frame, got.z, got.param1) == (
                    seq, sent.command, sent.frame, sent.z, sent.param1,
                )  # fmt: skip
                # MISSION_ITEM carries float32 degrees: 7.6e-6 deg (76 units of 1e-7) apart at 122 deg
                assert abs(got.x - sent.x * 1e7) <= 100 and abs(got.y - sent.y * 1e7) <= 100
            c.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED)

            if flavour != "lockstep":  # stream rates (the lock-step vehicle reports once a step)
                c.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_POSITION, 1, 1)
                time.sleep(0.3)
                while c.recv_match(blocking=False) is not None:
                    pass
                first = recv(c, "SYSTEM_TIME").time_boot_ms
                n, last = 0, first
                while last - first < 5000:
                    m = recv(c, ["GLOBAL_POSITION_INT", "SYSTEM_TIME"])
                    if m.get_type() == "GLOBAL_POSITION_INT":
                        n += 1
                    else:
                        last = m.time_boot_ms
                assert 4 <= n <= 6, n  # 1 Hz for 5 vehicle seconds
        finally:
            c.close()


# --------------------------------------------------------------------------------------------- MAVProxy
class MavProxy:
    """MAVProxy driven through its stdin, its output collected; no map, no console, no outputs."""

    def __init__(self, port: int, home: Path):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master=tcp:127.0.0.1:{port}", f"--state-basedir={home}"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=home,
            env={**os.environ, "HOME": str(home), "PYTHONUNBUFFERED": "1"},  # no user's ~/.mavinit.scr
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.out: list[str] = []
        self.reader = threading.Thread(target=self._read, name="mavproxy-out", daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)

    def send(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def expect(self, pattern: str, timeout: float = 10.0) -> re.Match:
        """The first line from now on matching ``pattern``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                continue
            self.out.append(line)
            found = re.search(pattern, line)
            if found:
                return found
        raise AssertionError(f"MAVProxy printed no {pattern!r} within {timeout} s:\n{''.join(self.out[-40:])}")

    def close(self) -> str:
        """Close its stdin (MAVProxy quits on end of input); everything it printed."""
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)
        self.reader.join(timeout=5)
        while not self.lines.empty():
            self.out.append(self.lines.get())
        return "".join(self.out)


@pytest.mark.parametrize("flavour", ["bare", "lockstep", SITL])
def test_mavproxy_connects_downloads_parameters_sets_guided_arms_and_loads_a_wpl_file(flavour, tmp_path):
    with Served(flavour, speedup=4.0 if flavour == "sitl" else 2.0) as v:
        mp = MavProxy(v.port, tmp_path)
        try:
            mp.expect(r"online system 1")
            n = int(mp.expect(r"Received (\d+) parameters", timeout=15).group(1))
            assert v.param_count_ok(n)
            deadline = time.monotonic() + v.guided_wait_s
            while True:  # ArduSub refuses GUIDED until its position estimate is ready
                mp.send("mode GUIDED")
                if mp.expect(r"DO_SET_MODE: (\w+)").group(1) == "ACCEPTED" or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert mp.out[-1].rstrip().endswith("DO_SET_MODE: ACCEPTED")
            mp.send("arm throttle")
            mp.expect(r"COMPONENT_ARM_DISARM: ACCEPTED")
            mp.send(f"wp load {WPL}")
            mp.expect(r"Loaded 9 waypoints from")
            mp.expect(r"MISSION_ACK: TYPE_MISSION: ACCEPTED")
            mp.send("wp list")
            mp.expect(r"Requesting 9 waypoints")
            mp.expect(r"Saved 9 waypoints")
        finally:
            out = mp.close()
        if v.fs is not None:
            assert v.fs.armed and v.fs.mode == GUIDED
            assert len(v.fs.mission_items) == 9
        assert "fence breach" not in out.lower()
        assert "Traceback" not in out and "DENIED" not in out and "UNSUPPORTED" not in out, out


# --------------------------------------------------------------------------------------------- MAVSDK
@pytest.mark.parametrize("flavour", ["bare", SITL])
def test_mavsdk_connects_reads_telemetry_uploads_a_mission_arms_and_moves_on_velocity_setpoints(flavour):
    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
    from mavsdk.plugins.mission_raw import MissionItem, MissionRaw
    from mavsdk.plugins.offboard import Offboard, VelocityNedYaw
    from mavsdk.plugins.telemetry import FlightMode, Telemetry

    with Served(flavour, speedup=4.0 if flavour == "sitl" else 5.0) as v:
        with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
            sdk.add_any_connection(f"tcpout://127.0.0.1:{v.port}")
            system = sdk.first_autopilot(10.0)
            assert system is not None, "MAVSDK discovered no autopilot"
            telemetry, action, raw = Telemetry(system), Action(system), MissionRaw(system)
            offboard, direct = Offboard(system), MavlinkDirect(system)

            position = wait_until(lambda: fixed(telemetry.position()), v.guided_wait_s, "a GPS fix")
            lat, lon = v.home
            assert abs(position.latitude_deg - lat) < 1e-5 and abs(position.longitude_deg - lon) < 1e-5
            assert telemetry.armed() is False

            items = [
                MissionItem(i, 0 if i == 0 else 6, 16, int(i == 0), 1, 0, 0, 0, 0, int((lat + 1e-4 * i) * 1e7),
                            int(lon * 1e7), -2.0 * (i > 0), 0)
                for i in range(3)
            ]  # fmt: skip
            raw.upload_mission(items)  # raises MissionRawError unless ACCEPTED
            down = raw.download_mission()
            assert [(m.seq, m.command, m.x) for m in down[1:]] == [(m.seq, m.command, m.x) for m in items[1:]]

            fields = {"target_system": 1, "target_component": 1, "command": mav.MAV_CMD_DO_SET_MODE, "confirmation": 0}
            fields |= {"param1": 1, "param2": GUIDED, "param3": 0, "param4": 0, "param5": 0, "param6": 0, "param7": 0}
            deadline = time.monotonic() + v.guided_wait_s
            while True:  # ArduSub refuses GUIDED until its position estimate is ready
                ack = direct.send_command(MavlinkMessage("COMMAND_LONG", 0, 0, 1, 1, json.dumps(fields)))
                result = json.loads(ack.fields_json)["result"]
                if result == mav.MAV_RESULT_ACCEPTED or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert result == mav.MAV_RESULT_ACCEPTED
            action.arm()
            wait_until(lambda: telemetry.armed() and telemetry.flight_mode() == FlightMode.OFFBOARD, 5, "armed GUIDED")

            start = telemetry.position_velocity_ned().position
            end = time.monotonic() + 8.0 / v.speedup  # 8 vehicle seconds
            while time.monotonic() < end:
                offboard.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
                time.sleep(0.1)
            moved = telemetry.position_velocity_ned().position
            assert moved.north_m - start.north_m > 3.0, (start, moved)  # 1 m/s north for 8 vehicle s
            assert abs(moved.east_m - start.east_m) < 1.5
            action.disarm()
            wait_until(lambda: not telemetry.armed(), 5, "disarmed")
