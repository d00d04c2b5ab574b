"""The back-seat's set-point as the front-seat and the log read it: heading, speed and surface survive the wire."""

from __future__ import annotations

import numpy as np
import pytest

from sim.uuv.interface import DEPTH_M, decode_command, depth_rate, encode_command


@pytest.mark.parametrize("depth", [0.0, 0.5, DEPTH_M, 2.3, 3.0, 4.0, 6.0, 20.0])
def test_a_vehicle_held_to_its_depth_is_never_read_as_surfacing(depth):
    # at its own pace the back-seat holds depth with a proportional vz: upward when the vehicle sits deeper than
    # its running depth. The firmware's calibration flights hovered a few decimetres deep, and a "surface" read
    # from that upward rate put random surfacings into the replay the vehicle is fitted to
    vz = depth_rate(depth, False)
    _, _, surface = decode_command(np.float32(1.0), np.float32(0.0), np.float32(vz), np.float32(0.0))
    assert not bool(surface), (depth, vz)
    _, _, up = decode_command(np.float32(1.0), np.float32(0.0), np.float32(depth_rate(depth, True)), np.float32(0.0))
    assert bool(up)


def test_lock_step_set_points_round_trip():
    heading = np.array([0.0, 1.0, -2.5])
    speed = np.array([0.0, 1.5, 2.0])
    surface = np.array([False, True, False])
    h, s, up = decode_command(*encode_command(heading, speed, surface))
    assert np.allclose(s, speed, atol=1e-6) and list(up) == list(surface)
    assert np.allclose(np.angle(np.exp(1j * (h - heading))), 0.0, atol=1e-6)
