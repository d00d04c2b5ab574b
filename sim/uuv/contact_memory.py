"""Where the back-seat last saw each sonar contact, and whether it still remembers it.

The forward-looking sonar (:mod:`sim.uuv.sonar`) sees only what lies in its field of
view, so an obstacle the vehicle turns away from drops out of sight while the vehicle is
still beside it.  The back-seat holds each contact's last-seen closest point for
:data:`CONTACT_MEMORY_S` and steers away from it meanwhile.  The expert autonomy and a
learned back-seat keep the same memory from the same reports (OBSTACLE_DISTANCE_3D
contacts), so a surrogate sees exactly what the expert remembers.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ContactMemory", "CONTACT_MEMORY_S"]

#: Seconds a sonar contact is remembered after it leaves the field of view.
CONTACT_MEMORY_S = 30.0


class ContactMemory:
    """Last-seen closest points (N, K) of each contact, with the time each was seen."""

    def __init__(self, hold_s: float = CONTACT_MEMORY_S):
        self.hold_s = float(hold_s)
        self.x: np.ndarray | None = None
        self.y: np.ndarray | None = None
        self.t: np.ndarray | None = None

    def update(self, t: float, contact_x: np.ndarray, contact_y: np.ndarray, detected: np.ndarray) -> np.ndarray:
        """Fold one step's detections in; returns which contacts (N, K) are known: seen within ``hold_s``."""
        x, y, seen_t = self.x, self.y, self.t
        if x is None or y is None or seen_t is None or seen_t.shape != contact_x.shape:
            x, y = contact_x.copy(), contact_y.copy()
            seen_t = np.full(contact_x.shape, -np.inf)
        self.x = np.where(detected, contact_x, x)
        self.y = np.where(detected, contact_y, y)
        self.t = np.where(detected, t, seen_t)
        return t - self.t <= self.hold_s
