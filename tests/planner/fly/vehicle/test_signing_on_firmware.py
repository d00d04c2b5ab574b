"""MAVLink 2 signing on ArduSub's firmware: given at bring-up, it makes the vehicle ignore an unsigned command from
a third client while ours are obeyed; on the firmware's channel 0, which takes unsigned messages whatever its key,
the run is refused in one line; a vehicle holding another key stops the run at the heartbeat. ``rapt-plan bridge``
gives the key the same way."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary  # noqa: E402
from planner.fly.flight import flight_from_plan  # noqa: E402
from planner.fly.vehicle.bringup import BringUpTimeouts  # noqa: E402
from planner.fly.vehicle.run import run_vehicle  # noqa: E402
from rapt.errors import LinkTimeoutError, RefusedError  # noqa: E402
from sim.uuv.missionfile import load_mission  # noqa: E402
from tests.support.loopback import free_port  # noqa: E402

ROOT = Path(__file__).resolve().parents[4]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
LAUNCH = launch_point(load_mission(ROOT / "examples" / "range2017.toml"))
KEY = bytes(range(32))

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")
pytestmark = [needs_firmware, pytest.mark.sitl, pytest.mark.integration, pytest.mark.slow]


def _ack(client, command: int, timeout_s: float = 2.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = client.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.2)
        if msg is not None and msg.command == command:
            return msg
    return None


def test_signing_protects_serial1_and_is_refused_on_channel_0():
    flight = flight_from_plan(PLAN, "pair2b")
    with ArduSubSitl(LAUNCH, speedup=10.0) as sitl:
        # SERIAL0 is the firmware's channel 0: the key is given, then the run refused, in one line
        with pytest.raises(RefusedError) as refused:
            run_vehicle(flight, sitl.connection, timeout_s=3.0, signing_key=KEY)
        line = str(refused.value)
        assert "\n" not in line and "channel 0" in line and "SERIAL1" in line, line

        # SERIAL1: the vehicle now signs with our key, ignores unsigned commands there, and flies our run
        steps: list = []
        result = run_vehicle(flight, f"tcp:127.0.0.1:{sitl.port + 2}", timeout_s=3.0, signing_key=KEY, say=steps.append)
        [signing] = [s for s in steps if s.name == "signing"]
        assert signing.status == "ok" and result.ended.startswith("wall-time limit")
        assert any(s.name == "arm" and s.status == "ok" for s in steps)  # our signed commands were obeyed

        # a third client on SERIAL2 without the key: its COMMAND_LONG is ignored; with the key, obeyed
        third = mavutil.mavlink_connection(f"tcp:127.0.0.1:{sitl.port + 3}", source_system=250, source_component=190)
        try:
            request = mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE
            version = mavutil.mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            third.mav.command_long_send(1, 1, request, 0, version, 0, 0, 0, 0, 0, 0)
            assert _ack(third, request) is None
            third.setup_signing(KEY, sign_outgoing=True)
            third.mav.command_long_send(1, 1, request, 0, version, 0, 0, 0, 0, 0, 0)
            ack = _ack(third, request)
            assert ack is not None and ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
        finally:
            third.close()

        # a run with another key: stopped at the heartbeat, the signatures named
        with pytest.raises(LinkTimeoutError) as other:
            run_vehicle(
                flight,
                f"tcp:127.0.0.1:{sitl.port + 2}",
                timeout_s=3.0,
                signing_key=bytes(32 - k for k in range(32)),
                timeouts=BringUpTimeouts(heartbeat=3.0),
            )
        assert "signatures do not match" in str(other.value) and "\n" not in str(other.value)


def _bridge(connection: str, key_file: Path) -> subprocess.Popen:
    """``rapt-plan bridge`` on ``connection`` with the key, its hub on a free loopback port."""
    hub = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    command = ["bridge", "--mavlink", connection, "--signing-key", str(key_file), "--allow-commands"]
    command += ["--zenoh-listen", hub]
    return subprocess.Popen(
        [sys.executable, "-m", "planner.cli", *command], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def test_the_bridge_gives_the_vehicle_its_key_and_refuses_channel_0(tmp_path):
    """``rapt-plan bridge --signing-key`` does what the run's bring-up does: on a disarmed vehicle that does not
    sign yet it sets the key with SETUP_SIGNING, checks that unsigned commands are ignored, and keeps bridging;
    on SERIAL0 it stops with the one line naming channel 0."""
    key_file = tmp_path / "key.bin"
    key_file.write_bytes(KEY)
    with ArduSubSitl(LAUNCH, speedup=10.0) as sitl:
        bridge = _bridge(f"tcp:127.0.0.1:{sitl.port + 2}", key_file)
        try:
            said = ""
            deadline = time.monotonic() + 90
            while "signs with our key" not in said and time.monotonic() < deadline and bridge.poll() is None:
                said += bridge.stderr.readline()
            assert "bridge: the vehicle signs with our key and ignores unsigned commands" in said, said
            assert bridge.poll() is None  # and it goes on bridging
            third = mavutil.mavlink_connection(
                f"tcp:127.0.0.1:{sitl.port + 3}", source_system=250, source_component=190
            )
            try:  # the key took: an unsigned command from a third client is ignored
                request = mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE
                version = mavutil.mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
                third.mav.command_long_send(1, 1, request, 0, version, 0, 0, 0, 0, 0, 0)
                assert _ack(third, request) is None
            finally:
                third.close()
        finally:
            bridge.terminate()
            bridge.communicate(timeout=30)
        assert bridge.returncode == 0

        refused = _bridge(f"tcp:127.0.0.1:{sitl.port}", key_file)
        _, stderr = refused.communicate(timeout=90)
        assert refused.returncode != 0
        line = stderr.strip().splitlines()[-1]
        assert "channel 0" in line and "SERIAL1" in line, stderr
