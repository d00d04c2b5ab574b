"""The command gates on their own: explicit times and positions, no threads, sockets or sleeps."""

from __future__ import annotations

import math

import pytest

from bridge import keys
from bridge.command_gate import GEOFENCE, INACTIVE, MODE, RATE_LIMITED, REFUSED, STALE, CommandGate, outward
from bridge.setpoint import Setpoint

HOLD = Setpoint(0.0, 0.0, 0.0, 0.0)  # no horizontal velocity: the geofence never refuses it
NORTH = Setpoint(1.0, 0.0, 0.0, 0.0)
T = 1000.0  # "now" of the tests, monotonic seconds
INSIDE = (50.0, 50.0, T)  # the middle of FENCE, just measured
FENCE = (0.0, 100.0, 0.0, 100.0)


def gate(**options) -> CommandGate:
    options.setdefault("allow_commands", True)
    return CommandGate(**options)


def test_only_the_active_source_passes_and_the_active_source_can_change():
    g = gate()
    assert g.active == keys.DEFAULT_ACTIVE
    assert g.check_source(keys.DEFAULT_ACTIVE) is None
    assert g.check_source("operator") == INACTIVE
    g.active = "operator"
    assert g.check_source("operator") is None
    assert g.check_source(keys.DEFAULT_ACTIVE) == INACTIVE
    assert CommandGate(active="operator").check_source("operator") is None


def test_a_fresh_link_and_allow_commands_let_a_set_point_through():
    assert gate().check(NORTH, T, None, T) is None  # no geofence, no rate limit: position not needed


def test_a_required_mode_refuses_set_points_in_any_other_mode_or_an_unknown_one():
    g = gate(required_mode=4)  # GUIDED
    assert g.check(HOLD, T, None, T, 4) is None
    assert g.check(HOLD, T, None, T, 19) == MODE  # MANUAL: a pilot's mode is never commanded
    assert g.check(HOLD, T, None, T, None) == MODE  # no HEARTBEAT yet
    assert g.check(HOLD, T, None, T - 10, 19) == STALE  # a silent link is named first
    assert gate().check(HOLD, T, None, T, 19) is None  # no required mode: the lock-step simulator's case


def test_without_allow_commands_everything_is_refused_first():
    g = gate(allow_commands=False, geofence=FENCE, max_rate_hz=1.0)
    assert g.check(HOLD, T, INSIDE, T) == REFUSED
    assert g.check(NORTH, T, None, None) == REFUSED  # refused before the link or the fence is looked at
    assert g.last_forward == -math.inf


def test_no_autopilot_or_a_silent_one_is_stale():
    g = gate(silence_s=2.0)
    assert g.check(HOLD, T, INSIDE, None) == STALE  # no autopilot known
    assert g.check(HOLD, T, INSIDE, T - 2.5) == STALE  # heard 2.5 s ago
    assert g.check(HOLD, T, INSIDE, T - 2.0) is None  # exactly silence_s ago still counts as heard
    assert g.check(HOLD, T, INSIDE, T) is None


def test_geofence_refuses_outward_velocity_near_an_edge():
    g = gate(geofence=FENCE, geofence_margin_m=20.0)
    near_north = (90.0, 50.0, T)
    assert g.check(NORTH, T, near_north, T) == GEOFENCE  # out through the north edge
    assert g.check(Setpoint(0.2, 0.3, 0.0, 0.0), T, near_north, T) == GEOFENCE  # still a northward part
    assert g.check(Setpoint(-1.0, 0.0, 0.0, 0.0), T, near_north, T) is None  # back inside
    assert g.check(Setpoint(0.0, 1.0, 0.0, 0.0), T, near_north, T) is None  # along the edge, east is far
    assert g.check(NORTH, T, INSIDE, T) is None  # far from every edge
    assert g.check(Setpoint(0.0, -1.0, 0.0, 0.0), T, (50.0, 20.0, T), T) == GEOFENCE  # the margin is inclusive


def test_geofence_refuses_horizontal_motion_without_a_fresh_position():
    g = gate(geofence=FENCE, silence_s=2.0)
    assert g.check(NORTH, T, None, T) == GEOFENCE
    assert g.check(NORTH, T, (50.0, 50.0, T - 2.5), T) == GEOFENCE  # the last position is too old
    assert g.check(NORTH, T, (50.0, 50.0, T - 2.0), T) is None
    assert g.check(Setpoint(0.0, 0.0, 0.5, 1.0), T, None, T) is None  # depth and yaw only: the fence is horizontal


def test_rate_limit_passes_one_set_point_per_interval():
    g = gate(max_rate_hz=2.0)  # one every 0.5 s
    assert g.check(HOLD, T, None, T) is None
    assert g.last_forward == T
    assert g.check(HOLD, T + 0.1, None, T + 0.1) == RATE_LIMITED
    assert g.check(HOLD, T + 0.4, None, T + 0.4) == RATE_LIMITED
    assert g.last_forward == T  # refusals do not restart the interval
    assert g.check(HOLD, T + 0.5, None, T + 0.5) is None
    assert g.last_forward == T + 0.5


def test_a_set_point_refused_by_an_earlier_gate_does_not_use_the_rate():
    g = gate(max_rate_hz=2.0, geofence=FENCE)
    assert g.check(NORTH, T, None, T) == GEOFENCE
    assert g.check(HOLD, T, None, None) == STALE
    assert g.last_forward == -math.inf
    assert g.check(HOLD, T + 0.1, None, T) is None


def test_without_a_rate_limit_every_set_point_passes():
    g = gate()
    assert all(g.check(HOLD, T + i * 1e-6, None, T) is None for i in range(100))


def test_bad_configuration_is_named():
    with pytest.raises(ValueError, match="geofence"):
        CommandGate(geofence=(10, 0, 0, 10))
    with pytest.raises(ValueError, match="geofence"):
        CommandGate(geofence=(0, 1, 0))
    with pytest.raises(ValueError, match="geofence_margin_m"):
        CommandGate(geofence_margin_m=-1)
    with pytest.raises(ValueError, match="max_rate_hz"):
        CommandGate(max_rate_hz=0)
    with pytest.raises(ValueError, match="silence_s"):
        CommandGate(silence_s=0)


def test_every_reason_is_a_bridge_counter():
    from bridge.mavlink_bridge import MavlinkBridge

    bridge = MavlinkBridge("udpin:127.0.0.1:1", allow_commands=True, geofence=FENCE, max_rate_hz=5.0)  # never started
    assert all(f"commands_{reason}" in bridge.stats for reason in (INACTIVE, REFUSED, STALE, GEOFENCE, RATE_LIMITED))
    assert bridge.gate.geofence == FENCE and bridge.geofence == FENCE and bridge.max_rate_hz == 5.0
    assert bridge.allow_commands and bridge.silence_s == bridge.gate.silence_s == 2.0


def test_outward_only_near_an_edge():
    fence = (0.0, 100.0, 0.0, 100.0)
    assert outward(fence, 20, 90, 50, 1.0, 0.0)
    assert not outward(fence, 20, 90, 50, -1.0, 0.0)
    assert not outward(fence, 20, 50, 50, 1.0, 1.0)
    assert outward(fence, 20, 50, 5, 0.0, -0.1)
    assert outward(fence, 20, 150, 50, 0.1, 0.0)  # outside, still heading out
