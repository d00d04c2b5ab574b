"""Latitude/longitude <-> the local metric frame of a range (x east, y north, metres).

The simulator, the autonomy and the mission files work in flat local metres around a
range origin, because every distance the scorer measures (closest approach, recovery
radius, area edges) is a few metres to a few kilometres and a flat frame makes that
geometry plain arithmetic.  Real vehicles, charts and MAVLink speak WGS84 latitude and
longitude, so this module converts at the edges (mission origins, the MAVLink bridge).

:class:`LocalFrame` is the local tangent plane (East-North-Up with the up component
dropped) at the origin, on the WGS84 ellipsoid: a point on the ellipsoid is mapped to
ECEF and projected onto the plane that touches the ellipsoid at the origin.  Near the
origin it reduces to ``x = N0 cos(lat0) dlon``, ``y = M0 dlat`` with ``M0`` and ``N0`` the
meridian and prime-vertical radii of curvature at the origin; unlike that first-order
form (which drifts by ~10 m at 10 km at mid latitudes because meridians converge) the
projection keeps plane distances within a few millimetres of the true ones out to
10 km.  :meth:`LocalFrame.to_latlon` inverts it (Newton iteration to 1e-8 m).

MAVLink carries latitude and longitude as ``int32`` degrees times 1e7 (about 1 cm):
:func:`to_degE7` and :func:`from_degE7` convert.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rapt.errors import InputError
from sim.uuv.angles import wrap_degrees

__all__ = ["LocalFrame", "to_degE7", "from_degE7", "WGS84_A", "WGS84_F", "DEGREE_DECIMALS"]

#: WGS84 semi-major axis (m) and flattening.
WGS84_A = 6_378_137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared


def _out(a: np.ndarray, scalar: bool):
    return float(a) if scalar else a


@dataclass(frozen=True)
class LocalFrame:
    """The local tangent plane at ``(origin_lat, origin_lon)`` (degrees, WGS84).

    ``x`` is metres east and ``y`` metres north of the origin.  Both conversions accept
    scalars or numpy arrays (broadcast together) and return floats or arrays alike.
    """

    origin_lat: float
    origin_lon: float
    meridian_radius: float = field(init=False, repr=False)
    prime_vertical_radius: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lat, lon = float(self.origin_lat), float(self.origin_lon)
        if not (math.isfinite(lat) and -90.0 < lat < 90.0):
            raise InputError(f"origin_lat: expected degrees strictly between -90 and 90, got {self.origin_lat!r}")
        if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
            raise InputError(f"origin_lon: expected degrees in [-180, 180], got {self.origin_lon!r}")
        object.__setattr__(self, "origin_lat", lat)
        object.__setattr__(self, "origin_lon", float(wrap_degrees(np.asarray(lon))))
        phi = math.radians(lat)
        w = 1.0 - _E2 * math.sin(phi) ** 2
        object.__setattr__(self, "prime_vertical_radius", WGS84_A / math.sqrt(w))
        object.__setattr__(self, "meridian_radius", WGS84_A * (1.0 - _E2) / w**1.5)

    # ------------------------------------------------------------------ forward
    def _enu(self, phi: np.ndarray, dlam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """East/north of ellipsoid points (radians; longitude relative to the origin)."""
        phi0 = math.radians(self.origin_lat)
        s0, c0 = math.sin(phi0), math.cos(phi0)
        sphi, cphi = np.sin(phi), np.cos(phi)
        n = WGS84_A / np.sqrt(1.0 - _E2 * sphi**2)
        # ECEF in a frame rotated so the origin's meridian is at longitude 0.
        X = n * cphi * np.cos(dlam)
        Y = n * cphi * np.sin(dlam)
        Z = n * (1.0 - _E2) * sphi
        n0 = self.prime_vertical_radius
        X0, Z0 = n0 * c0, n0 * (1.0 - _E2) * s0
        east = Y
        north = -s0 * (X - X0) + c0 * (Z - Z0)
        return east, north

    def to_local(self, lat, lon):
        """Degrees -> ``(x_east_m, y_north_m)``."""
        scalar = np.ndim(lat) == 0 and np.ndim(lon) == 0
        lat_a = np.asarray(lat, dtype=float)
        lon_a = np.asarray(lon, dtype=float)
        if np.any(np.abs(lat_a) > 90.0):
            raise InputError("lat: latitudes must lie in [-90, 90] degrees")
        dlam = np.radians(wrap_degrees(lon_a - self.origin_lon))
        x, y = self._enu(np.radians(lat_a), dlam)
        return _out(x, scalar), _out(y, scalar)

    # ------------------------------------------------------------------ inverse
    def to_latlon(self, x, y):
        """``(x_east_m, y_north_m)`` -> degrees ``(lat, lon)`` (longitude in [-180, 180))."""
        scalar = np.ndim(x) == 0 and np.ndim(y) == 0
        xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        m0 = self.meridian_radius
        p0 = self.prime_vertical_radius * math.cos(math.radians(self.origin_lat))
        phi = math.radians(self.origin_lat) + ya / m0
        dlam = xa / p0
        for _ in range(50):
            e, n = self._enu(phi, dlam)
            rx, ry = xa - e, ya - n
            phi = np.clip(phi + ry / m0, -math.pi / 2, math.pi / 2)
            dlam = dlam + rx / p0
            if np.all(np.abs(rx) < 1e-8) and np.all(np.abs(ry) < 1e-8):
                break
        lat = np.degrees(phi)
        lon = wrap_degrees(self.origin_lon + np.degrees(dlam))
        return _out(lat, scalar), _out(lon, scalar)


#: Decimal places of a latitude or longitude in the files a range loads: MAVLink's degE7, what the vehicle
#: holds (about 1 cm). It also keeps another CPU's last-digit differences in the maths out of those files.
DEGREE_DECIMALS = 7


def to_degE7(deg) -> np.ndarray:
    """Degrees -> MAVLink ``int32`` degrees * 1e7 (rounded to the nearest unit, ~1 cm)."""
    d = np.asarray(deg, dtype=float)
    if not np.all(np.isfinite(d)) or np.any(np.abs(d) > 180.0):
        raise InputError("deg: expected finite latitudes/longitudes within [-180, 180] degrees")
    return np.rint(d * 1e7).astype(np.int32)


def from_degE7(value) -> np.ndarray:
    """MAVLink ``int32`` degrees * 1e7 -> degrees (float64)."""
    return np.asarray(value, dtype=np.int64) / 1e7
