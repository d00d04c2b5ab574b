"""A robot's state space ``[θ, φ]`` in radians and in the unit cube the searches work in.

Every part of the self-righting study converts between the two and compares states in
them: joint and body angles, some of which wrap round a full turn.  These helpers are
that one convention, kept in one place.
"""

from __future__ import annotations

import numpy as np

from rapt.manifold import full_turn
from sim.robots import Robot

__all__ = ["space_bounds", "to_unit", "toward", "row_keys"]


def space_bounds(robot: Robot, planar: bool) -> np.ndarray:
    """Radian ranges of ``[θ, φ]``: joint ranges, then pitch (planar) or roll and pitch."""
    body = [[-np.pi, np.pi]] if planar else [[-np.pi, np.pi], [-np.pi / 2, np.pi / 2]]
    return np.concatenate([robot.joint_bounds, np.asarray(body)]).reshape(-1, 2)


def to_unit(angles: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Radians → unit cube of ``[lo, hi]``; a full-turn coordinate is wrapped into its range first."""
    span = hi - lo
    a = np.asarray(angles, dtype=float)
    full = full_turn(lo, hi)  # periodic coordinate: wrap into range
    a = np.where(full, lo + np.mod(a - lo, 2 * np.pi), a)
    return np.clip((a - lo) / span, 0.0, 1.0)


def toward(a: np.ndarray, b: np.ndarray, periodic) -> np.ndarray:
    """``b − a`` in angles, the shorter way round on the ``periodic`` coordinates.

    :mod:`rapt.manifold` and :mod:`rapt.transitions` work on the (cos, sin) embedding and
    have no angle difference of their own, so this is the one copy.
    """
    return np.where(periodic, np.mod(b - a + np.pi, 2 * np.pi) - np.pi, b - a)


def row_keys(A: np.ndarray) -> np.ndarray:
    """Hashable keys of rows, equal for rows equal to ~1e-9."""
    R = np.ascontiguousarray(np.round(np.asarray(A, float), 9) + 0.0)
    return R.view(np.dtype((np.void, R.dtype.itemsize * R.shape[1]))).ravel()
