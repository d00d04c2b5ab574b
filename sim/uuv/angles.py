"""Angle wrapping, the one place sim/uuv does it.

Headings and bearings are compass radians wrapped to (-pi, pi] (as MAVLink's
ATTITUDE.yaw reports them); longitudes are degrees wrapped to [-180, 180).  The two
keep their own half-open ends and formulas because results must stay bit-identical
to what the simulator, the front-seat and the mission files produced before.
"""

from __future__ import annotations

import numpy as np

__all__ = ["wrap_angle", "wrap_degrees"]


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Radians wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def wrap_degrees(d: np.ndarray) -> np.ndarray:
    """Degrees wrapped to [-180, 180)."""
    return (d + 180.0) % 360.0 - 180.0
