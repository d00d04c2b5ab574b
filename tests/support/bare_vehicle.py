"""Our front-seat as a bare ArduSub on a loopback UDP port, serving in a thread for the length of a test."""

from __future__ import annotations

import contextlib
import socket
import threading

from sim.uuv.ardusub.frontseat import FrontSeat
from tests.support.loopback import free_port, no_new_threads

#: Fast, yet slow enough that a loaded 2-core machine does not starve the vehicle for seconds of its time.
SPEEDUP = 25.0


@contextlib.contextmanager
def bare_vehicle(mission, u, speedup: float = SPEEDUP):
    """Yields (the bridge's connection string, the front-seat); every thread it started is gone afterwards."""
    port = free_port(socket.SOCK_DGRAM)
    with no_new_threads():
        fs = FrontSeat(mission, u, f"udpin:127.0.0.1:{port}", bare=True, speedup=speedup)
        thread = threading.Thread(target=fs.serve, name="bare-vehicle", daemon=True)
        thread.start()
        try:
            yield f"udpout:127.0.0.1:{port}", fs
        finally:
            fs.stop()
            thread.join(timeout=5)
            fs.close()
