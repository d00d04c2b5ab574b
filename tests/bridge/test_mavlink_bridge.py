"""The bridge that composes link, vehicle commands and relay: what its constructor refuses."""

from __future__ import annotations

import pytest

from bridge.mavlink_bridge import MavlinkBridge

pytestmark = [pytest.mark.integration]


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="geofence"):
        MavlinkBridge("udpin:127.0.0.1:1", geofence=(10, 0, 0, 10))
    with pytest.raises(ValueError, match="max_rate_hz"):
        MavlinkBridge("udpin:127.0.0.1:1", max_rate_hz=0)
    with pytest.raises(ValueError, match="signing_key"):
        MavlinkBridge("udpin:127.0.0.1:1", signing_key=b"short")
