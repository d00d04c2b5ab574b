"""Navigation error: an INS that drifts under water and a Kalman filter that fixes it by GPS.

Submerged, the position estimate random-walks away from the truth (``ins_drift_m_per_s``
of drift per square-root second); on the surface each GPS fix (``gps_sigma_m``) is fused
by a Kalman filter.  The batch filter is the per-axis closed form of filterpy's
``KalmanFilter`` with F = H = I (:func:`filterpy_filter` builds that filter for one
vehicle, and a test holds the two to the same numbers).  Deterministic runs have no error.
"""

from __future__ import annotations

import numpy as np

from sim.uuv.mission import Vehicle

__all__ = ["Navigation", "filterpy_filter"]


class Navigation:
    """Estimated-minus-true position error of N vehicles and its variance."""

    def __init__(self, n: int, spec: Vehicle):
        self.spec = spec
        self.ex = np.zeros(n)
        self.ey = np.zeros(n)
        self.var = np.zeros(n)

    def step(self, dt: float, surfaced: np.ndarray, z: np.ndarray | None) -> None:
        """Advance by ``dt``; ``z`` holds 4 standard normal draws per vehicle (None: no error)."""
        if z is None:
            return
        q = self.spec.ins_drift_m_per_s**2 * dt
        self.ex += np.sqrt(q) * z[:, 0]
        self.ey += np.sqrt(q) * z[:, 1]
        self.var += q  # predict: P <- F P F' + Q
        r = self.spec.gps_sigma_m**2
        gain = np.where(surfaced, self.var / (self.var + r), 0.0)  # update: K = P / (P + R)
        zx = self.spec.gps_sigma_m * z[:, 2]  # error of the GPS fix
        zy = self.spec.gps_sigma_m * z[:, 3]
        self.ex += gain * (zx - self.ex)
        self.ey += gain * (zy - self.ey)
        self.var *= 1.0 - gain

    def estimate(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x + self.ex, y + self.ey


def filterpy_filter(spec: Vehicle, dt: float):
    """The same filter for a single vehicle as a filterpy ``KalmanFilter`` (state: x, y)."""
    from filterpy.kalman import KalmanFilter

    kf = KalmanFilter(dim_x=2, dim_z=2)
    kf.F = np.eye(2)
    kf.H = np.eye(2)
    kf.P = np.zeros((2, 2))
    kf.Q = np.eye(2) * spec.ins_drift_m_per_s**2 * dt
    kf.R = np.eye(2) * spec.gps_sigma_m**2
    return kf
