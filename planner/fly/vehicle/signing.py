"""MAVLink signing with the vehicle, for ``run --mavlink`` (a bring-up step) and ``rapt-plan bridge`` alike.

The vehicle is given our key by SETUP_SIGNING only while it is disarmed, and signing counts only once
the vehicle shows it: its heartbeats come signed with our key, and it ignores an unsigned command on
our link. ArduPilot accepts every unsigned message on its channel 0 (``GCS_Signing.cpp``: "always accept
channel 0, assumed to be secure channel"; SITL's SERIAL0, a USB port, BlueOS's main endpoint), so a
link that still answers an unsigned command is refused: signing there would protect nothing.
"""

from __future__ import annotations

import time
from typing import Any

from planner.fly.lifecycle import wait_for
from rapt.errors import RefusedError, RunError

__all__ = ["SIGNED", "sign_vehicle"]

#: What a link that passed :func:`sign_vehicle` does, in one line.
SIGNED = "the vehicle signs with our key and ignores unsigned commands on this link"
#: How long the vehicle may take to sign its heartbeats once given the key.
KEY_TAKEN_S = 5.0


def sign_vehicle(link: Any, connection: str) -> str:
    """Sign with the vehicle on ``link`` (a :class:`bridge.mavlink_bridge.MavlinkBridge` holding the key, the
    vehicle heard); :data:`SIGNED` once done. RefusedError when the vehicle is armed without our key, or
    when ``connection`` is its channel 0; RunError when it does not take the key."""
    got = link.latest("HEARTBEAT")
    if got is None or not got[0].get_signed():
        autopilot = link.autopilot
        if autopilot is not None and autopilot.armed:
            raise RefusedError(
                "--signing-key: the vehicle is armed and does not sign with this key; the key is given to a "
                "vehicle only while it is disarmed"
            )
        asked = time.monotonic()
        link.setup_signing()

        def signs() -> bool:
            hb = link.latest("HEARTBEAT")
            return hb is not None and hb[1] > asked and bool(hb[0].get_signed())

        if not wait_for(signs, KEY_TAKEN_S, poll_s=0.02):
            raise RunError("--signing-key: the vehicle did not take the key (its heartbeats are still unsigned)")
    link.accept_unsigned = False
    if link.accepts_unsigned():
        raise RefusedError(
            f"--signing-key: the vehicle answers unsigned commands on {connection} (ArduPilot's channel 0: "
            "SITL's SERIAL0, a USB port, BlueOS's main endpoint), so signing protects nothing there; connect "
            "through another serial or UDP endpoint (SERIAL1 or later)"
        )
    return SIGNED
