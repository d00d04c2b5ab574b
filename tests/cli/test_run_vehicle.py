"""`rapt-plan run PLAN --scenario ID --mavlink CONN` refuses what it must, in one line, before commanding anything."""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from typer.testing import CliRunner  # noqa: E402

from planner.cli import app  # noqa: E402
from tests.support.loopback import free_port  # noqa: E402

M = mavutil.mavlink
runner = CliRunner()
PLAN = str(Path(__file__).resolve().parents[2] / "field_plans" / "range2017" / "plan.json")


class HeartbeatOnly:
    """A vehicle that only says who it is (type, mode, armed) and records what it is sent."""

    def __init__(self, device: str, mav_type: int, mode: int, armed: bool):
        self.conn = mavutil.mavlink_connection(device, source_system=1, source_component=1, dialect="ardupilotmega")
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        self.heartbeat = M.MAVLink_heartbeat_message(mav_type, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, mode, 4, 3)
        self.received: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="heartbeat-only", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        next_beat = 0.0
        while not self._stop.is_set():
            if time.monotonic() >= next_beat:
                self.conn.mav.send(self.heartbeat)
                next_beat = time.monotonic() + 0.1
            if select.select([self.conn.fd], [], [], 0.01)[0]:
                while (msg := self.conn.recv_msg()) is not None:
                    if msg.get_type() != "BAD_DATA":
                        self.received.append(msg.get_type())

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.conn.close()


@contextlib.contextmanager
def vehicle(mav_type: int, mode: int = 19, armed: bool = False):
    port = free_port(socket.SOCK_STREAM)
    peer = HeartbeatOnly(f"tcpin:127.0.0.1:{port}", mav_type, mode, armed)
    try:
        yield f"tcp:127.0.0.1:{port}", peer
    finally:
        peer.close()


def _run(connection: str, *extra: str):
    return runner.invoke(
        app, ["run", PLAN, "--scenario", "pair2b", "--mavlink", connection, "--heartbeat-timeout", "3", *extra]
    )


def _one_line_error(result, expect: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and expect in lines[0], result.output


def test_an_unreachable_address_is_one_line():
    port = free_port(socket.SOCK_STREAM)  # nobody listens there
    _one_line_error(_run(f"tcp:127.0.0.1:{port}"), f"--mavlink tcp:127.0.0.1:{port}: could not open it")


def test_a_vehicle_that_is_not_a_submarine_is_refused_before_anything_is_commanded():
    with vehicle(M.MAV_TYPE_QUADROTOR) as (conn, peer):
        _one_line_error(_run(conn), "the vehicle is a MAV_TYPE_QUADROTOR, not a submarine")
    assert set(peer.received) <= {"HEARTBEAT"}, peer.received


def test_a_vehicle_armed_in_another_mode_is_refused_before_anything_is_commanded():
    with vehicle(M.MAV_TYPE_SUBMARINE, mode=19, armed=True) as (conn, peer):
        _one_line_error(_run(conn), "already armed in MANUAL")
    assert set(peer.received) <= {"HEARTBEAT"}, peer.received


def test_options_that_need_our_simulator_are_refused_with_mavlink():
    _one_line_error(_run("tcp:127.0.0.1:1", "--speedup", "10"), "--speedup: not with --mavlink")
    _one_line_error(_run("tcp:127.0.0.1:1", "--watchdog-action", "panic"), "--watchdog-action: expected one of")
