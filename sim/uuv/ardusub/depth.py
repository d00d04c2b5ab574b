"""Depth as a state of its own: the torpedo model (:mod:`sim.uuv.vehicle`) is horizontal only.

The lock-step front-seat treats depth as a command (surfaced or at ``DEPTH_M``); a bare
autopilot must instead integrate the vertical velocity a client asks for, approach a
depth target at a bounded speed and report "surfaced" (GPS fix, ``World.surfaced``) only
near the surface.  Measured on ArduSub SITL: GUIDED vz 0.5 m/s gave 0.52 m/s; SURFACE
mode rose at about 1.2 m/s and then stayed at the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Depth", "MAX_VZ", "SURFACE_VZ", "SURFACED_M"]

#: Fastest vertical speed (m/s, either way).
MAX_VZ = 1.0
#: Ascent rate in SURFACE mode (m/s).
SURFACE_VZ = 1.0
#: At or above this depth (m) the vehicle counts as surfaced: GPS fix, position fixes.
SURFACED_M = 0.1


@dataclass
class Depth:
    """Depth in metres (>= 0, positive down) and the last vertical speed (NED, + down)."""

    depth: float = 0.0
    vz: float = 0.0

    @property
    def surfaced(self) -> bool:
        return self.depth <= SURFACED_M

    def toward(self, target: float, dt: float, limit: float = MAX_VZ) -> float:
        """The vertical speed reaching ``target`` as fast as allowed, without overshooting in ``dt``."""
        if dt <= 0:
            return 0.0
        return max(-limit, min(limit, (max(0.0, target) - self.depth) / dt))

    def step(self, vz: float, dt: float) -> None:
        vz = max(-MAX_VZ, min(MAX_VZ, float(vz)))
        new = max(0.0, self.depth + vz * dt)
        self.vz = (new - self.depth) / dt if dt > 0 else 0.0
        self.depth = new
