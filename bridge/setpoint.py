"""The back-seat set-point: the one message a back-seat may send towards the vehicle.

A back-seat publishes it as JSON on ``rapt/<vehicle>/command/<source>``; the bridge turns a
set-point from the active source into ``SET_POSITION_TARGET_LOCAL_NED`` (velocity + yaw).
Validation lives here so that a bad set-point is refused, with a reason, before it gets near
MAVLink.  A bad set-point raises the built-in ``ValueError`` (not a :mod:`rapt.errors`
class), so that this module stays as cheap to import as :mod:`bridge.keys`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from numbers import Real

__all__ = ["Setpoint", "MAX_TICK_MS"]

#: ``time_boot_ms`` is a uint32.
MAX_TICK_MS = 2**32 - 1


def _finite(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(float(value)):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Setpoint:
    """Velocity (m/s, NED: ``vz`` positive down, so negative rises) and absolute yaw (rad).

    ``tick_ms`` is the simulation tick or the ``time_boot_ms`` the set-point answers; it is
    passed through as ``time_boot_ms`` (0 when None), which lets a benchmark match a set-point
    to the telemetry that caused it.
    """

    vx: float
    vy: float
    vz: float
    yaw: float
    tick_ms: int | None = None

    def __post_init__(self):
        for name in ("vx", "vy", "vz", "yaw"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        tick = self.tick_ms
        if tick is not None:
            if isinstance(tick, bool) or not isinstance(tick, int) or not 0 <= tick <= MAX_TICK_MS:
                raise ValueError(f"tick_ms: expected null or an int in [0, 2**32), got {tick!r}")

    def to_json(self) -> bytes:
        """The wire form ``{"tick_ms", "vx", "vy", "vz", "yaw"}``."""
        return json.dumps(
            {"tick_ms": self.tick_ms, "vx": self.vx, "vy": self.vy, "vz": self.vz, "yaw": self.yaw},
            separators=(",", ":"),
        ).encode()

    @classmethod
    def from_json(cls, payload: bytes | str) -> Setpoint:
        """Parse the wire form; ValueError names the first bad field."""
        try:
            data = json.loads(payload)
        except (ValueError, UnicodeDecodeError) as error:
            raise ValueError(f"payload: not JSON ({error})") from None
        if not isinstance(data, dict):
            raise ValueError(f"payload: expected a JSON object, got {type(data).__name__}")
        missing = [k for k in ("vx", "vy", "vz", "yaw") if k not in data]
        if missing:
            raise ValueError(f"{missing[0]}: missing from the set-point")
        return cls(data["vx"], data["vy"], data["vz"], data["yaw"], data.get("tick_ms"))
