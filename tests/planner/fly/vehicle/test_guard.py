"""The guard's options and script: what it watches, and bad options in one line (its flights are
test_guard_on_firmware.py's)."""

from __future__ import annotations

import pytest

from planner.fly.vehicle.guard import GuardOptions, guard_script, heartbeat_rate
from rapt.errors import InputError


def test_the_options_and_the_script_say_what_the_guard_watches():
    script = guard_script(12.5, (1, 191)).decode()
    assert "local TIMEOUT_MS = 12500" in script and "local OWNER_COMPID = 191" in script and "{{" not in script
    with pytest.raises(InputError, match=r"^--guard-timeout: expected 2 to 600 seconds"):
        GuardOptions(timeout_s=0.5)
    with pytest.raises(InputError, match=r"^--guard-path: expected the script's path on the vehicle ending \.lua"):
        GuardOptions(path="scripts/guard.py")


def test_the_heartbeat_keeps_five_beats_per_timeout_of_the_vehicles_clock():
    assert heartbeat_rate(10.0, 1.0) == 1.0  # a vehicle in real time: a ground station's 1 Hz is plenty
    assert heartbeat_rate(10.0, 40.0) == pytest.approx(20.0)  # SITL at speed-up 40: 0.5 vehicle s apart
