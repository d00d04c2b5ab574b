"""Tidal current by time of day (section 3.7.1), with seeded perturbations when stochastic.

The autonomy knows the tide table (it crabs against the predicted current); the world
adds the perturbation it cannot predict.
"""

from __future__ import annotations

import numpy as np

from sim.uuv.mission import Current

__all__ = ["tidal_current"]


def tidal_current(current: Current, seconds_of_day: np.ndarray, scale=1.0, offset=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Predicted current (east, north) in m/s at each time of day (seconds after midnight).

    ``scale`` and ``offset`` (m/s along ``direction_deg``) give the true current of a
    biased range (:mod:`sim.uuv.bias`); the defaults are the tide table itself.
    """
    hours = np.asarray(seconds_of_day, dtype=float) / 3600.0
    phase = 2.0 * np.pi * (hours - current.peak_hour) / current.period_h
    speed = current.speed * np.cos(phase) * scale + offset
    heading = np.deg2rad(current.direction_deg)
    return speed * np.sin(heading), speed * np.cos(heading)
