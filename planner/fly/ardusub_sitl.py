"""ArduSub's own firmware built for software in the loop, started the way tests and rehearsals need it.

A range's vehicle runs ArduSub; its SITL build (``./waf configure --board sitl && ./waf sub``)
is the real firmware with a simulated BlueROV2 under it: its EKF, modes, failsafes and
stream rates, not our model of them. :class:`ArduSubSitl` starts the binary named by
``ARDUSUB_SITL`` in a temporary directory of its own (a wiped parameter store, the
firmware's defaults file beside the binary), with its home at a mission's launch point, at
a speed-up, on an instance whose TCP ports are free; it waits until SERIAL0 listens and
stops the process at exit, whatever happened.

SITL listens on every interface (the firmware has no option for that); everything RAPT
sends it goes to 127.0.0.1.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

from rapt.errors import InputError, LinkTimeoutError, MissingFileError
from sim.uuv.geo import LocalFrame
from sim.uuv.mission import Mission

__all__ = ["ENV", "ArduSubSitl", "launch_point", "sitl_binary"]

#: The environment variable naming the ArduSub SITL binary.
ENV = "ARDUSUB_SITL"
#: SERIAL0's TCP port of instance 0; instance N uses 5760 + 10 N (and 5762/5763 + 10 N).
BASE_PORT = 5760


def _is_number(value: object) -> bool:
    """Whether ``value`` is a finite real number (a parameter's value)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def sitl_binary() -> Path | None:
    """The binary ``ARDUSUB_SITL`` names, or None when the variable is unset."""
    value = os.environ.get(ENV)
    return Path(value) if value else None


def launch_point(mission: Mission) -> tuple[float, float, float, float]:
    """SITL's ``--home`` for ``mission``: (lat, lon, alt, heading).

    Where a range team puts the vehicle in the water: the mission's launch point converted
    from its local frame (:class:`sim.uuv.geo.LocalFrame` at the mission's origin, as the
    MAVLink front-seat converts), on the surface, heading (compass degrees) for the first
    waypoint as the modelled vehicle starts.
    """
    lx, ly = mission.launch
    lat, lon = LocalFrame(mission.origin_lat, mission.origin_lon).to_latlon(float(lx), float(ly))
    heading = 0.0
    if mission.waypoints:
        wx, wy = mission.waypoints[0]
        heading = math.degrees(math.atan2(wx - lx, wy - ly)) % 360.0
    return float(lat), float(lon), 0.0, heading


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _free_instance(first: int = 1, last: int = 60) -> int:
    """An instance number whose three SERIAL ports are free (instance 0 is left to a user's own SITL)."""
    for instance in range(first, last + 1):
        base = BASE_PORT + 10 * instance
        if all(_port_free(base + k) for k in (0, 2, 3)):
            return instance
    raise LinkTimeoutError(f"instance: no free ArduSub SITL instance in {first}..{last}; stop other SITL processes")


#: What a range sets on a vehicle before its first RAPT run: scripting on, for the onboard guard.
PREPARED = {"SCR_ENABLE": 1}


class ArduSubSitl:
    """One ArduSub SITL process: ``with ArduSubSitl(home=(lat, lon, alt, heading), speedup=10) as sitl:``.

    ``sitl.connection`` is the pymavlink connection string of SERIAL0 (``tcp:127.0.0.1:PORT``).
    ``binary`` defaults to ``ARDUSUB_SITL``; the defaults file is ``sub.parm`` beside it.
    ``parameters`` are defaults of this run's own, after ``sub.parm`` (a test's firmware that
    never gets a position, say); the parameter store is wiped at every start either way. Lua
    scripting is on (:data:`PREPARED`), as on a vehicle made ready for RAPT's onboard guard
    (docs/onboard-guard.md); ``parameters={"SCR_ENABLE": 0}`` gives a vehicle that is not.
    """

    def __init__(
        self,
        home: tuple[float, float, float, float],
        *,
        speedup: float = 10.0,
        binary: str | Path | None = None,
        defaults: str | Path | None = None,
        start_timeout_s: float = 30.0,
        parameters: dict[str, float] | None = None,
    ):
        binary = Path(binary) if binary is not None else sitl_binary()
        if binary is None:
            raise InputError(f"binary: set {ENV} to the ArduSub SITL binary (see docs/sil-and-vehicle-link.md)")
        if not binary.is_file():
            raise MissingFileError(f"{ENV}: {str(binary)!r} does not exist; point it at the ArduSub SITL binary")
        if not os.access(binary, os.X_OK):
            raise InputError(f"{ENV}: {str(binary)!r} is not executable; chmod +x it, or point {ENV} at the built one")
        defaults = Path(defaults) if defaults is not None else binary.with_name("sub.parm")
        if not defaults.is_file():
            raise MissingFileError(f"defaults: {str(defaults)!r} does not exist; put ArduSub's sub.parm beside it")
        if not speedup > 0:
            raise InputError(f"speedup: expected a factor > 0, got {speedup!r}")
        self.binary, self.defaults, self.home = binary, defaults, home
        self.speedup = float(speedup)
        self.parameters = {**PREPARED, **(parameters or {})}
        for name, value in self.parameters.items():
            if not name.replace("_", "").isalnum() or not name.isupper() or not _is_number(value):
                raise InputError(f"parameters: {name}={value!r} is not an ArduPilot parameter and a number")
        self.start_timeout_s = start_timeout_s
        self.instance = -1
        self.port = -1
        self.directory: Path | None = None
        self.process: subprocess.Popen | None = None

    @property
    def connection(self) -> str:
        return f"tcp:127.0.0.1:{self.port}"

    def __enter__(self) -> ArduSubSitl:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> ArduSubSitl:
        """Start the firmware and wait until SERIAL0 accepts a connection."""
        self.instance = _free_instance()
        self.port = BASE_PORT + 10 * self.instance
        # a directory of its own: its parameter store (eeprom.bin) starts empty, so every boot of this SITL starts
        # from the defaults, and a reboot it is asked for (--guard-reboot) keeps what was set, as a vehicle does
        self.directory = Path(tempfile.mkdtemp(prefix="ardusub-sitl-"))
        shutil.copy(self.defaults, self.directory / "sub.parm")
        defaults = "sub.parm"
        if self.parameters:
            lines = "".join(f"{name} {value:g}\n" for name, value in self.parameters.items())
            (self.directory / "run.parm").write_text(lines)
            defaults += ",run.parm"
        lat, lon, alt, heading = self.home
        command = [
            str(self.binary),
            "--model", "vectored",
            "--speedup", f"{self.speedup:g}",
            "--defaults", defaults,
            "-I", str(self.instance),
            "--home", f"{lat},{lon},{alt},{heading}",
            "--serial0", "tcp:0",  # do not wait for a client
        ]  # fmt: skip
        log = open(self.directory / "sitl.log", "wb")  # noqa: SIM115 - the process writes it until stop()
        try:
            self.process = subprocess.Popen(command, cwd=self.directory, stdout=log, stderr=subprocess.STDOUT)
        except OSError as exc:  # wrong architecture, not a program: leave no directory behind
            self.stop()
            raise InputError(
                f"{ENV}: {str(self.binary)!r} cannot be run ({exc.strerror}); build it for this machine "
                "(docs/sil-and-vehicle-link.md)"
            ) from exc
        finally:
            log.close()
        try:
            self._wait_until_listening()
        except BaseException:  # a refusal, a timeout, Ctrl-C: never leave the firmware running
            self.stop()
            raise
        return self

    def _wait_until_listening(self) -> None:
        assert self.process is not None
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                said = self._last_log_line()
                raise LinkTimeoutError(
                    f"{ENV}: the firmware exited with code {self.process.returncode} at start"
                    + (f" ({said})" if said else "")
                )
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    pass
                # that probe was SERIAL0's one client; let the firmware see it gone before the real one connects
                time.sleep(0.2)
                return
            except OSError:
                time.sleep(0.1)
        raise LinkTimeoutError(f"{ENV}: SERIAL0 (port {self.port}) did not listen within {self.start_timeout_s} s")

    def _last_log_line(self) -> str:
        """The firmware's last non-empty line of output (why it stopped, as it said it)."""
        try:
            text = (self.directory / "sitl.log").read_text(errors="replace") if self.directory else ""
        except OSError:
            return ""
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        return lines[-1][:200] if lines else ""

    def stop(self) -> None:
        """Stop the process by its id (SIGTERM, then SIGKILL) and remove its directory."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        if self.directory is not None:
            shutil.rmtree(self.directory, ignore_errors=True)
            self.directory = None
