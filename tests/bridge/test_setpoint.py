"""The back-seat's set-point on the bus."""

from __future__ import annotations

import pytest

from bridge.setpoint import Setpoint


def test_setpoint_validation_names_the_field():
    sp = Setpoint.from_json(b'{"tick_ms": 7, "vx": 1, "vy": 2.5, "vz": -0.5, "yaw": 0.1}')
    assert (sp.tick_ms, sp.vx, sp.vy, sp.vz, sp.yaw) == (7, 1.0, 2.5, -0.5, 0.1)
    assert Setpoint.from_json(sp.to_json()) == sp
    for payload, field in [
        (b'{"vx": 1, "vy": 2, "vz": 3}', "yaw"),
        (b'{"vx": NaN, "vy": 0, "vz": 0, "yaw": 0}', "vx"),
        (b'{"vx": 0, "vy": 0, "vz": 0, "yaw": 0, "tick_ms": -1}', "tick_ms"),
        (b"[1, 2]", "payload"),
        (b"\xff", "payload"),
    ]:
        with pytest.raises(ValueError, match=field):
            Setpoint.from_json(payload)
