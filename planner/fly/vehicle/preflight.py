"""The bring-up's steps that prepare the vehicle itself before a run: MAVLink signing and the onboard guard.

They are :class:`planner.fly.vehicle.bringup.BringUp`'s (a mixin of it). What they have in common is that
each changes something on the vehicle that outlasts the run: its signing key, a script on its storage.
So each does it only while the vehicle is disarmed, and checks the result by what the vehicle does next.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NoReturn

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from planner.fly.vehicle.guard import (  # noqa: E402
    MAV_CMD_SCRIPTING,
    REPORT_NAME,
    SCR_ENABLE,
    SCRIPTING_CMD_STOP_AND_RESTART,
    VERSION,
    GuardOptions,
    guard_script,
    heartbeat_rate,
)
from planner.fly.vehicle.signing import sign_vehicle  # noqa: E402
from rapt.errors import InputError, LinkTimeoutError, RefusedError, RunError  # noqa: E402

__all__ = ["Preflight", "result_name"]


class Preflight:
    """Signing (:meth:`signing`) and the onboard guard (:meth:`guard`), as bring-up steps."""

    if TYPE_CHECKING:  # what BringUp gives its mixin
        bridge: Any
        connection: str
        timeouts: Any
        guard_options: GuardOptions | None
        pace: float

        def _fail(self, name: str, error: Exception) -> NoReturn: ...
        def _ok(self, name: str, detail: str) -> None: ...
        def note(self, name: str, status: str, detail: str) -> None: ...
        def _wait(self, get: Callable[[], object], timeout: float) -> Any: ...
        def _armed(self) -> bool: ...
        def heartbeat(self) -> None: ...
        def streams(self) -> None: ...
        def estimate(self) -> None: ...

    def signing(self) -> None:
        """With ``--signing-key``: the vehicle signs with our key (given it by SETUP_SIGNING, only while it is
        disarmed), unsigned frames are refused from then on, and the link must be one where the vehicle
        refuses unsigned commands too. ArduPilot accepts every unsigned message on its channel 0 (SITL's
        SERIAL0, a USB port, BlueOS's main endpoint): signing there protects nothing, so the run is refused."""
        if self.bridge.signing_key is None:
            return
        try:
            self._ok("signing", sign_vehicle(self.bridge, self.connection))
        except (RefusedError, RunError) as exc:
            self._fail("signing", exc)

    def guard(self) -> None:
        """Install the onboard guard (:mod:`planner.fly.vehicle.guard`) while the vehicle is disarmed: our
        heartbeat at the rate it needs, the script by MAVLink FTP, scripting restarted, its report heard."""
        options = self.guard_options
        if options is None:
            self.note(
                "guard", "note", "no onboard guard (--no-guard): if this computer stops, nothing surfaces the vehicle"
            )
            return
        if self._armed():
            self._fail(
                "guard", RefusedError("bring-up guard: the vehicle is armed; the guard is installed only disarmed")
            )
        pace = self.pace = self._pace()
        self.bridge.heartbeat_hz = heartbeat_rate(options.timeout_s, pace)
        enabled = self._parameter(SCR_ENABLE)
        if enabled is None:
            self._fail(
                "guard",
                InputError(
                    f"bring-up guard: the vehicle has no scripting (no {SCR_ENABLE} parameter); "
                    "fly with --no-guard, or load a firmware with Lua scripting"
                ),
            )
        if enabled < 1 and not options.reboot:  # refused before anything is written on the vehicle
            self._fail(
                "guard",
                RefusedError(
                    f"bring-up guard: scripting is off on the vehicle ({SCR_ENABLE} 0); add --guard-reboot to turn "
                    "it on and reboot the disarmed vehicle, or fly with --no-guard"
                ),
            )
        owner = (self.bridge.source_system, self.bridge.source_component)
        try:
            # scripting that was never on has no scripts directory yet: it is made (one level, as a crew would)
            script = guard_script(options.timeout_s, owner)
            self.bridge.put_file(script, options.path, timeout=self.timeouts.guard / 4, make_directory=True)
        except (RefusedError, LinkTimeoutError) as exc:
            self._fail("guard", RefusedError(f"bring-up guard: {exc}; fly with --no-guard to run without it"))
        if enabled < 1:
            self._reboot_with_scripting()
        else:
            asked = self._command(MAV_CMD_SCRIPTING, (SCRIPTING_CMD_STOP_AND_RESTART,))
            if asked != mavlink.MAV_RESULT_ACCEPTED:
                self._fail("guard", RefusedError(f"bring-up guard: scripting restart refused ({result_name(asked)})"))
        since = time.monotonic()
        if self._wait(lambda: self._guard_report(since), self.timeouts.guard) is None:
            self._fail(
                "guard",
                RunError(
                    f"bring-up guard: {options.path} installed but not running (no {REPORT_NAME} report within "
                    f"{self.timeouts.guard:g} s); see the vehicle's STATUSTEXT for the script's error, or fly with --no-guard"
                ),
            )
        self._ok(
            "guard",
            f"v{VERSION} running from {options.path}: SURFACE after {options.timeout_s:g} s (vehicle time) without "
            f"heartbeat {owner[0]}/{owner[1]} in GUIDED; heartbeat {self.bridge.heartbeat_hz:.1f} Hz "
            f"(vehicle clock x{pace:.1f})",
        )

    def _reboot_with_scripting(self) -> None:
        """Scripting on and a reboot, the operator having consented; then the link's checks again."""
        if self._armed():
            self._fail("guard", RefusedError("bring-up guard: the vehicle armed itself; not rebooting it"))
        self.bridge.set_parameter(SCR_ENABLE, 1.0)
        if self._parameter(SCR_ENABLE) != 1.0:
            self._fail("guard", RefusedError(f"bring-up guard: the vehicle did not take {SCR_ENABLE} 1"))
        self.note("guard", "note", f"{SCR_ENABLE} set to 1; rebooting the vehicle (--guard-reboot)")
        self._command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, (1,))

        def rebooting() -> bool | None:  # its heartbeat has stopped
            hb = self.bridge.autopilot
            return True if hb is None or time.monotonic() - hb.monotonic_s > 1.5 else None

        self._wait(rebooting, 10.0)
        self.heartbeat()
        self.streams()
        self.estimate()

    def _pace(self) -> float:
        """How many times faster than the wall's the vehicle's clock runs (from its ATTITUDE reports)."""
        first = self.bridge.latest("ATTITUDE")
        if first is None:
            return 1.0

        def later():
            got = self.bridge.latest("ATTITUDE")
            return got if got is not None and got[1] - first[1] >= 0.5 else None

        last = self._wait(later, 2.0)
        if last is None or last[0].time_boot_ms <= first[0].time_boot_ms:
            return 1.0
        return (last[0].time_boot_ms - first[0].time_boot_ms) / 1000.0 / (last[1] - first[1])

    def _parameter(self, name: str, tries: int = 3, wait_s: float = 1.0) -> float | None:
        """Parameter ``name``'s value from the vehicle (None when it does not answer: it has no such parameter)."""

        def answer(asked: float):
            got = self.bridge.latest("PARAM_VALUE")
            return got if got is not None and got[1] >= asked and got[0].param_id == name else None

        for _ in range(tries):
            asked = time.monotonic()
            self.bridge.request_parameter(name)
            got = self._wait(functools.partial(answer, asked), wait_s)
            if got is not None:
                return float(got[0].param_value)
        return None

    def _guard_report(self, since: float) -> bool | None:
        got = self.bridge.latest("NAMED_VALUE_FLOAT")
        if got is not None and got[1] >= since and got[0].name == REPORT_NAME and int(got[0].value) == VERSION:
            return True
        return None

    def _command(self, command: int, params: Sequence[float]) -> int | None:
        try:
            return self.bridge.command_long(command, params)
        except TimeoutError:
            return None


def result_name(result: int | None) -> str:
    """A MAV_RESULT's name ("no COMMAND_ACK" for None)."""
    if result is None:
        return "no COMMAND_ACK"
    entry = mavlink.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else str(result)
