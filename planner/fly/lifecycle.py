"""The loop's pieces as processes of their own: run until SIGINT or SIGTERM, then stop cleanly.

``rapt-plan frontseat``, ``bridge``, ``autonomy`` and ``log`` each run one piece of the
software-in-the-loop setup (or of the real one: the bridge joins a real vehicle) as a
long-lived process.  How a piece is started, kept running and shut down is the same for
all of them, and lives here rather than in the command line.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager

from bridge.vehicle_commands import ARDUSUB_MODES
from rapt.errors import RefusedError

GUIDED_MODE = ARDUSUB_MODES["GUIDED"]

__all__ = ["wait_for", "wait_for_signal", "serve_until_signal", "run_until_signal", "arm_when_heard"]


def wait_for(condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
    """Poll ``condition`` until it holds or ``timeout_s`` of wall time pass; whether it held."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() >= deadline:
            return False
        time.sleep(poll_s)
    return True


def wait_for_signal() -> None:
    """Block until SIGINT/SIGTERM, so a process stops cleanly."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    while not stop.wait(0.1):  # a timed wait, so the handler runs promptly
        pass


def serve_until_signal(frontseat) -> None:
    """Serve a front-seat (:class:`sim.uuv.ardusub.frontseat.FrontSeat`) until a stop signal, then stop and close it."""
    thread = threading.Thread(target=frontseat.serve, daemon=True)
    thread.start()
    wait_for_signal()
    frontseat.stop()
    thread.join(timeout=5)
    frontseat.close()


def run_until_signal(session, start: Callable[[], AbstractContextManager]) -> None:
    """Run the piece ``start()`` opens on the bus ``session`` until a stop signal; the session is closed after."""
    try:
        with start():
            wait_for_signal()
    finally:
        session.close()


def arm_when_heard(link, timeout_s: float = 30.0, *, guided_s: float = 120.0) -> bool:
    """Once the bridge ``link`` hears the vehicle: GUIDED, then arm.  False if it is not heard in ``timeout_s``.

    ArduSub refuses GUIDED until its position estimate is ready (about 40 s after a cold
    boot), so GUIDED is asked again every half second for up to ``guided_s``.  The vehicle
    is armed only while its heartbeat shows GUIDED (checked before every try: armed in a
    pilot mode with no pilot it would drift), and arming is asked again until accepted;
    RefusedError if either never happens.
    """
    if not wait_for(lambda: link.target is not None, timeout_s, poll_s=0.05):
        return False
    deadline, result, step = time.monotonic() + guided_s, None, "GUIDED"
    while time.monotonic() < deadline:
        mode = link.autopilot.custom_mode if link.autopilot is not None else None
        if mode != GUIDED_MODE:
            step, result = "GUIDED", link.set_mode("GUIDED")
            if result == 0:  # MAV_RESULT_ACCEPTED: arm once the heartbeat shows it
                wait_for(lambda: link.autopilot is not None and link.autopilot.custom_mode == GUIDED_MODE, 5.0)
                continue
        else:
            step, result = "arming", link.arm(True)
            if result == 0:
                return True
        time.sleep(0.5)
    raise RefusedError(
        f"--arm: the vehicle refused {step} for {guided_s:g} s (last result {result}); "
        "is its position estimate ready and are its pre-arm checks passing?"
    )
