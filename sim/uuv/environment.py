"""Tidal current by time of day (section 3.7.1), with seeded perturbations when stochastic.

The autonomy knows the tide table (it crabs against the predicted current); the world
adds the perturbation it cannot predict.
"""

from __future__ import annotations

import numpy as np

from sim.uuv.mission import Current

__all__ = ["tidal_current", "biased_tide"]


def tidal_current(
    current: Current, seconds_of_day: np.ndarray, scale=1.0, offset=0.0, cross=0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted current (east, north) in m/s at each time of day (seconds after midnight).

    ``scale``, ``offset`` (m/s along ``direction_deg``) and ``cross`` (m/s towards
    ``direction_deg + 90``) give the true current of a biased range (:mod:`sim.uuv.bias`);
    the defaults are the tide table itself.
    """
    hours = np.asarray(seconds_of_day, dtype=float) / 3600.0
    phase = 2.0 * np.pi * (hours - current.peak_hour) / current.period_h
    speed = current.speed * np.cos(phase) * scale + offset
    heading = np.deg2rad(current.direction_deg)
    east, north = speed * np.sin(heading), speed * np.cos(heading)
    if np.any(cross != 0.0):  # the neutral bias adds nothing, bit for bit
        east, north = east + cross * np.cos(heading), north - cross * np.sin(heading)
    return east, north


def biased_tide(current: Current, seconds_of_day: np.ndarray, bias) -> tuple[np.ndarray, np.ndarray]:
    """The current a biased range flies at ``seconds_of_day`` (already shifted by the bias's
    ``start_time``): ``bias`` is a :class:`sim.uuv.bias.Bias`, or its per-vehicle arrays."""
    return tidal_current(current, seconds_of_day, bias.current_scale, bias.current_offset, bias.current_cross)
