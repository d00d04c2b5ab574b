"""The bus's key scheme."""

from __future__ import annotations

import pytest
import zenoh

from bridge import keys


def test_keys_follow_the_scheme():
    assert keys.telemetry("uuv1", "HEARTBEAT") == "rapt/uuv1/mavlink/HEARTBEAT"
    assert keys.raw("uuv1") == "rapt/uuv1/mavlink/raw"
    assert keys.command("uuv1", "*") == "rapt/uuv1/command/*"
    assert keys.virtual("uuv1", "OBSTACLE_DISTANCE_3D") == "rapt/uuv1/virtual/OBSTACLE_DISTANCE_3D"
    assert zenoh.KeyExpr(keys.everything("uuv1")).includes(keys.virtual("uuv1", "BATTERY_STATUS"))
    assert not zenoh.KeyExpr(keys.telemetry("uuv1", "*")).intersects(keys.virtual("uuv1", "*"))
    assert keys.active("uuv1") == "rapt/uuv1/control/active"
    assert keys.status("uuv1", "autonomy") == "rapt/uuv1/status/autonomy"
    assert keys.meta("uuv1", "scenario") == "rapt/uuv1/meta/scenario"
    assert keys.alive("uuv1", "bridge") == "rapt/uuv1/alive/bridge"
    assert keys.everything("uuv1") == "rapt/uuv1/**"
    assert zenoh.KeyExpr(keys.everything("uuv1")).includes(keys.command("uuv1", "x"))
    assert keys.split("rapt/uuv1/mavlink/HEARTBEAT") == ("uuv1", "mavlink", "HEARTBEAT")
    with pytest.raises(ValueError, match="vehicle"):
        keys.raw("a/b")
    with pytest.raises(ValueError, match="source"):
        keys.command("uuv1", "**")
    with pytest.raises(ValueError, match="msg_name"):
        keys.virtual("uuv1", "A/B")
