"""The onboard guard: a Lua script on the vehicle that surfaces it when this computer stops flying it.

Nothing on an ArduSub vehicle notices that the back-seat in GUIDED is gone: we are an onboard
computer, not the ground station its failsafe watches, and GUIDED only stops obeying old
velocity targets, so a vehicle at depth drifts on with nobody commanding it. The guard
(``rapt_guard.lua`` beside this module) runs on the autopilot itself. It watches our HEARTBEAT
and, when it has been silent for the guard's timeout (vehicle seconds) while the vehicle is
armed in GUIDED, switches it to SURFACE and says so in a STATUSTEXT. It never acts in any other
mode and never touches a failsafe parameter.

Bring-up (:meth:`planner.fly.vehicle.bringup.BringUp.guard`) installs it each run with MAVLink FTP
into the scripts directory, restarts scripting, and checks the script reports itself. Our
heartbeat rate is raised so that the guard hears :data:`BEATS_PER_TIMEOUT` beats per timeout of
the vehicle's clock, however fast that clock runs against the wall's (SITL's speed-up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rapt.errors import InputError

__all__ = [
    "GuardOptions",
    "DEFAULT_GUARD",
    "guard_script",
    "heartbeat_rate",
    "VERSION",
    "REPORT_NAME",
    "DEFAULT_PATH",
    "SCR_ENABLE",
    "MAV_CMD_SCRIPTING",
    "SCRIPTING_CMD_STOP_AND_RESTART",
]

#: The script's version, in its STATUSTEXT and its once-a-second NAMED_VALUE_FLOAT.
VERSION = 1
#: The NAMED_VALUE_FLOAT the running guard sends every second (value: :data:`VERSION`).
REPORT_NAME = "RAPTGUARD"
#: Where ArduPilot's scripting reads scripts on SITL and on Linux boards (BlueOS's Navigator); on a
#: Pixhawk-class board's SD card it is ``APM/scripts/`` (docs/onboard-guard.md).
DEFAULT_PATH = "scripts/rapt_guard.lua"
DEFAULT_TIMEOUT_S = 10.0
#: Heartbeats the guard hears per timeout at least (vehicle clock).
BEATS_PER_TIMEOUT = 5
#: The parameter that turns ArduPilot's scripting on (read at boot: changing it needs a reboot).
SCR_ENABLE = "SCR_ENABLE"
#: MAV_CMD_SCRIPTING and its STOP_AND_RESTART: scripts are read again without a reboot.
MAV_CMD_SCRIPTING = 42701
SCRIPTING_CMD_STOP_AND_RESTART = 3

_SOURCE = Path(__file__).with_name("rapt_guard.lua")


@dataclass(frozen=True)
class GuardOptions:
    """How bring-up installs the guard: its ``timeout_s`` (vehicle seconds of silence before SURFACE), the
    script's ``path`` on the vehicle, and whether the operator consents (``reboot``) to turning scripting on
    and rebooting the vehicle, only ever while it is disarmed."""

    timeout_s: float = DEFAULT_TIMEOUT_S
    path: str = DEFAULT_PATH
    reboot: bool = False

    def __post_init__(self) -> None:
        if not (
            isinstance(self.timeout_s, (int, float)) and math.isfinite(self.timeout_s) and 2 <= self.timeout_s <= 600
        ):
            raise InputError(f"--guard-timeout: expected 2 to 600 seconds, got {self.timeout_s!r}")
        if not (
            isinstance(self.path, str) and self.path.endswith(".lua") and self.path.isascii() and len(self.path) < 200
        ):
            raise InputError(f"--guard-path: expected the script's path on the vehicle ending .lua, got {self.path!r}")


#: The guard a run installs unless told otherwise.
DEFAULT_GUARD = GuardOptions()


def guard_script(timeout_s: float, owner: tuple[int, int]) -> bytes:
    """The guard's Lua source for a silence of ``timeout_s`` of the heartbeat of ``owner`` (system, component)."""
    values = {
        "version": str(VERSION),
        "timeout_ms": str(int(round(timeout_s * 1000))),
        "owner_sysid": str(int(owner[0])),
        "owner_compid": str(int(owner[1])),
    }
    text = _SOURCE.read_text()
    for name, value in values.items():
        text = text.replace("{{" + name + "}}", value)
    return text.encode()


def heartbeat_rate(timeout_s: float, pace: float) -> float:
    """Our heartbeat rate (Hz, wall) so that the guard hears :data:`BEATS_PER_TIMEOUT` beats per ``timeout_s`` of a
    vehicle clock running ``pace`` times the wall's; never below the 1 Hz a ground station expects."""
    return max(1.0, BEATS_PER_TIMEOUT * max(pace, 0.0) / timeout_s)
