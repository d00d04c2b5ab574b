"""A run of ``rapt-plan run --mavlink`` on the firmware killed mid-scenario, and a listener that watches the
vehicle on another of its ports meanwhile: the tests of what is left when the range laptop dies."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

__all__ = ["Monitor", "KilledRun", "kill_mid_scenario"]


class Monitor:
    """A listener on the firmware's second port (SERIAL1): its clock, modes and STATUSTEXTs. It sends no
    heartbeat, so it is no ground station the firmware's own failsafe would watch."""

    def __init__(self, port: int):
        self.link = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250, source_component=190)
        self.now_ms = -1
        self.modes: list[tuple[int, int]] = []  # (vehicle ms, custom_mode) of each autopilot heartbeat
        self.texts: list[tuple[int, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="monitor", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        asked = 0.0
        while not self._stop.is_set():
            if time.monotonic() - asked > 2.0:  # its stream on this port, whatever the port's defaults
                self.link.mav.request_data_stream_send(1, 1, mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
                asked = time.monotonic()
            msg = self.link.recv_match(blocking=True, timeout=0.1)
            if msg is None or msg.get_srcSystem() != 1:
                continue
            if hasattr(msg, "time_boot_ms"):
                self.now_ms = max(self.now_ms, int(msg.time_boot_ms))
            if msg.get_type() == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.modes.append((self.now_ms, int(msg.custom_mode)))
            elif msg.get_type() == "STATUSTEXT":
                self.texts.append((self.now_ms, msg.text))

    def wait(self, test, timeout_s: float, what: str):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if (got := test()) is not None:
                return got
            time.sleep(0.01)
        raise AssertionError(f"no {what} within {timeout_s} s; modes {self.modes[-5:]}, texts {self.texts[-5:]}")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.link.close()


@dataclass
class KilledRun:
    lines: list[str]  # what the run printed on stderr (its bring-up steps)
    killed_ms: int  # the vehicle's time at the kill
    mode_at_kill: int  # the vehicle's mode then (ArduSub custom_mode)
    returncode: int


def kill_mid_scenario(
    connection: str, monitor: Monitor, plan: Path, scenario: str, flown_s: float, *args: str
) -> KilledRun:
    """``rapt-plan run PLAN --scenario SCENARIO --mavlink CONNECTION ARGS`` killed with SIGKILL ``flown_s`` vehicle
    seconds after its scenario clock started (as ``monitor`` sees the vehicle's clock)."""
    lines: list[str] = []
    run = subprocess.Popen(
        [sys.executable, "-m", "planner.cli", "run", str(plan), "--scenario", scenario, "--mavlink", connection, *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "COLUMNS": "200"},
    )
    reader = threading.Thread(target=lambda: lines.extend(run.stderr), daemon=True)
    reader.start()
    try:
        monitor.wait(lambda: any(" clock " in line for line in lines) or None, 180, "scenario clock")
        start_ms = monitor.now_ms
        monitor.wait(lambda: monitor.now_ms >= start_ms + flown_s * 1000 or None, 120, "the flight")
        mode = monitor.modes[-1][1]
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=10)
        return KilledRun(lines, monitor.now_ms, mode, run.returncode)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(timeout=10)
        reader.join(timeout=5)
