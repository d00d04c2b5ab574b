"""The live view in a process of its own: nothing it does competes with the control path for the interpreter.

A :class:`~bridge.live_view.LiveView` inside a process that also commands the vehicle shares
that process's interpreter lock: encoding a map, a client's burst of subscriptions or a
reconnecting client all hold up, now and then, the thread that answers the vehicle's report
with its set-point. In a process of its own it shares only the machine and the bus, which routes
it just the few keys it reads; and it runs on CPU time nothing else wants (Linux's SCHED_IDLE), so
on a busy laptop the process that commands the vehicle is never the one that waits. A starved
view falls behind, not the run: when it runs it shows the latest of each message, and its rings
keep the last events (bridge.live_view.EVENT_RING).

:class:`LiveViewProcess` starts ``python -m bridge.live_process`` joined to the bus like any
process of the range (the run's loopback endpoint, or the range's keys as role ``logger``) and
returns once its server is up; a port in use, or a bus it cannot join, raises the child's own
one-line error. The child runs until SIGTERM or SIGINT and prints ``ready ws://HOST:PORT``
on stdout once it serves.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Self

from rapt.errors import InputError, LinkError, RaptError

from . import keys
from .live_view import LiveView, parse_address

__all__ = ["LiveViewProcess", "READY", "main"]

#: The child's one line on stdout once its server is up, followed by its URL.
READY = "ready"
#: How long the child may take to join the bus and start serving.
START_TIMEOUT_S = 30.0
#: The child's CPU priority below the run's (``os.nice``) where SCHED_IDLE is not offered.
NICE = 10
#: How long the child has to close its server and session after SIGTERM.
STOP_TIMEOUT_S = 10.0


class LiveViewProcess:
    """A live view of vehicle ``vehicle`` on ``host:port`` in a child process (see the module docstring).

    The child joins the bus through ``connect`` (Zenoh endpoints of the process that holds the bus,
    on the loopback bus) or, with ``keys_dir``, as ``role`` on the range's secure bus. ``maps``:
    GeoJSON documents by name, shown from the start. ``port`` 0 takes a free port (:attr:`port`
    tells which once started).
    """

    def __init__(
        self,
        *,
        vehicle: str = keys.DEFAULT_VEHICLE,
        host: str = "127.0.0.1",
        port: int = 0,
        connect: Sequence[str] = (),
        keys_dir: str | Path | None = None,
        role: str = "logger",
        maps: dict[str, dict] | None = None,
        start_timeout_s: float = START_TIMEOUT_S,
    ):
        if keys_dir is None and not connect:
            raise InputError("live view: give the bus's endpoints (connect) or the range's keys (keys_dir)")
        keys.everything(vehicle)  # validates the name before anything starts
        self.vehicle, self.host, self.port = vehicle, host, int(port)
        self._connect, self._keys_dir, self._role = list(connect), keys_dir, role
        self._maps = dict(maps or {})
        self._timeout = start_timeout_s
        self._dir: tempfile.TemporaryDirectory | None = None
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        """What to give Foxglove's "Open connection": ``ws://host:port``."""
        return f"ws://{self.host}:{self.port}"

    def _command(self, directory: Path) -> list[str]:
        command = [sys.executable, "-m", "bridge.live_process", "--vehicle", self.vehicle]
        command += ["--listen", f"{self.host}:{self.port}"]
        if self._keys_dir is not None:
            command += ["--bus-keys", str(self._keys_dir), "--bus-role", self._role]
        for endpoint in self._connect:
            command += ["--connect", endpoint]
        for name, document in self._maps.items():
            path = directory / f"{name}.geojson"
            path.write_text(json.dumps(document, allow_nan=False))
            command += ["--map", f"{name}={path}"]
        return command

    def start(self) -> Self:
        """Start the child and wait until it serves; its one-line error (as :class:`InputError`) if it cannot."""
        if self.process is not None:
            raise RuntimeError("start: the live view process was already started")
        self._dir = tempfile.TemporaryDirectory(prefix="rapt-live-")
        directory = Path(self._dir.name)
        errors = directory / "stderr.txt"
        with errors.open("wb") as stderr:
            self.process = subprocess.Popen(
                self._command(directory), stdout=subprocess.PIPE, stderr=stderr, stdin=subprocess.DEVNULL
            )
        try:
            line = self._ready_line()
        except BaseException:
            self.close()
            raise
        self.port = int(line.rsplit(":", 1)[1])
        return self

    def _ready_line(self) -> str:
        """The child's ``ready`` line, or its error once it has exited (or a timeout)."""
        assert self.process is not None and self.process.stdout is not None and self._dir is not None
        deadline = time.monotonic() + self._timeout
        out = self.process.stdout
        while time.monotonic() < deadline:
            readable, _, _ = select.select([out], [], [], 0.05)
            if readable:
                line = out.readline().decode(errors="replace").strip()
                if line.startswith(READY + " "):
                    return line
            if self.process.poll() is not None:
                said = (Path(self._dir.name) / "stderr.txt").read_text(errors="replace").strip().splitlines()
                reason = said[-1] if said else f"it exited with code {self.process.returncode}"
                raise InputError(reason) if self.process.returncode == 2 else LinkError(f"live view: {reason}")
        raise LinkError(f"live view: not serving within {self._timeout:g} s; is the bus up?")

    def close(self) -> None:
        """Stop the child (SIGTERM, then SIGKILL after :data:`STOP_TIMEOUT_S`) and remove its files. Idempotent."""
        process, self.process = self.process, None
        if process is not None:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
                try:
                    process.wait(timeout=STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            if process.stdout is not None:
                process.stdout.close()
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def _arguments(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m bridge.live_process", description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", default=keys.DEFAULT_VEHICLE)
    ap.add_argument("--listen", default="127.0.0.1:0", metavar="[HOST:]PORT", help="where the WebSocket server serves")
    ap.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="a Zenoh endpoint of the bus")
    ap.add_argument("--bus-keys", type=Path, default=None, metavar="DIR", help="the range's keys (rapt-plan bus-keys)")
    ap.add_argument("--bus-role", default="logger", help="the role joined as with --bus-keys")
    ap.add_argument(
        "--map", action="append", default=[], metavar="NAME=FILE", help="a GeoJSON map shown from the start"
    )
    return ap.parse_args(argv)


def _maps(pairs: Sequence[str]) -> dict[str, dict]:
    out = {}
    for pair in pairs:
        name, sep, path = pair.partition("=")
        if not sep or not name:
            raise InputError(f"--map: expected NAME=FILE, got {pair!r}")
        try:
            out[name] = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"--map: cannot read GeoJSON {path!r} ({exc}); give a GeoJSON file") from None
    return out


def _session(args: argparse.Namespace):
    import zenoh

    from .session import open_session

    if args.bus_keys is not None:
        from .range_keys import role_config

        try:
            return zenoh.open(role_config(args.bus_keys, args.bus_role))
        except zenoh.ZError as exc:
            raise LinkError(
                f"--bus-keys: role {args.bus_role!r} could not join the hub ({str(exc).split(' at ')[0]})"
            ) from None
    if not args.connect:
        raise InputError("--connect: give the bus's Zenoh endpoint (or --bus-keys DIR)")
    return open_session(connect=args.connect)


def _yield_the_cpu() -> None:
    """This process, and every thread it starts from now on (Zenoh's, the server's), runs only on CPU time
    nothing else wants: Linux's SCHED_IDLE, else (another system) :data:`NICE`."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        os.nice(NICE)


def main(argv: Sequence[str] | None = None) -> int:
    """Serve the live view until SIGTERM or SIGINT; exit 2 with a one-line error on bad input, 1 on a link error."""
    _yield_the_cpu()
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    session = None
    try:
        args = _arguments(argv)
        host, port = parse_address(args.listen, "--listen")
        maps = _maps(args.map)
        session = _session(args)
        with LiveView(session, vehicle=args.vehicle, host=host, port=port, maps=maps) as view:
            print(f"{READY} {view.url}", flush=True)  # the one line the parent reads
            while not stop.wait(0.5):
                pass
    except RaptError as exc:
        print(exc, file=sys.stderr)
        return 2 if isinstance(exc, InputError) else 1
    finally:
        if session is not None:
            session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
