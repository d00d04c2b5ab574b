"""The safety gates between a back-seat's set-points and the vehicle, as one pure object.

:class:`CommandGate` decides whether a set-point may go to MAVLink and, if not, says why. It
holds the gates' configuration and their state (the active source, the time of the last
set-point let through) and nothing else: no threads, sockets, sleeps or clock. The caller
passes ``now`` (monotonic seconds) and what it knows of the vehicle, which is what makes the
gates testable with explicit times and reusable by anything else that must send the vehicle
a set-point (a watchdog) under the same rules as the bridge.

The gates, in the order they are checked (each refusal names the bridge counter
``commands_<reason>``):

1. :meth:`CommandGate.check_source` — ``"inactive"``: only the active source may command.
   Asked before the payload is parsed, so nothing from another source is ever parsed.
   (The bridge then parses the payload: ``"invalid"`` is its reason, not a gate's.)
2. :meth:`CommandGate.check`:

   * ``"refused"`` — ``allow_commands`` is off;
   * ``"stale"`` — no autopilot known, or none heard within ``silence_s``;
   * ``"mode"`` — ``required_mode`` is set and the autopilot's last HEARTBEAT is in another
     mode (a real vehicle is commanded in GUIDED only, never in a pilot's mode);
   * ``"geofence"`` — a horizontal velocity while the position is unknown or older than
     ``silence_s``, or heading out through an edge the vehicle is within the margin of;
   * ``"rate_limited"`` — less than ``1 / max_rate_hz`` since the last set-point let through.

   ``None`` means "forward it", and the gate counts it as forwarded for the rate limit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from rapt.errors import InputError

from . import keys
from .setpoint import Setpoint

__all__ = ["GEOFENCE", "INACTIVE", "MODE", "RATE_LIMITED", "REFUSED", "STALE", "CommandGate", "Fence", "outward"]

#: (north_min, north_max, east_min, east_max) in metres, local NED.
Fence = tuple[float, float, float, float]

#: Refusal reasons, in the order the gates are checked.
INACTIVE = "inactive"
REFUSED = "refused"
STALE = "stale"
MODE = "mode"
GEOFENCE = "geofence"
RATE_LIMITED = "rate_limited"


def outward(fence: Fence, margin: float, north: float, east: float, vn: float, ve: float) -> bool:
    """True when velocity (vn, ve) heads out through an edge of ``fence`` that (north, east) is within ``margin`` of."""
    n_min, n_max, e_min, e_max = fence
    return (
        (vn > 0 and north >= n_max - margin)
        or (vn < 0 and north <= n_min + margin)
        or (ve > 0 and east >= e_max - margin)
        or (ve < 0 and east <= e_min + margin)
    )


def _geofence(value: Sequence[float] | None) -> Fence | None:
    if value is None:
        return None
    try:
        n_min, n_max, e_min, e_max = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError("geofence: expected (north_min, north_max, east_min, east_max) in metres") from None
    if not all(math.isfinite(v) for v in (n_min, n_max, e_min, e_max)) or n_min >= n_max or e_min >= e_max:
        raise InputError(f"geofence: need finite north_min < north_max and east_min < east_max, got {tuple(value)}")
    return n_min, n_max, e_min, e_max


class CommandGate:
    """Whether a set-point may reach the vehicle: ``check_source`` then ``check`` (see the module docstring).

    Configuration (read-only after construction): ``allow_commands``, ``silence_s`` (how old
    the last frame and the last position may be), ``geofence`` and ``geofence_margin_m``,
    ``max_rate_hz`` (None: no limit). State: :attr:`active` (the source whose set-points are
    considered; set it when the bus names another) and :attr:`last_forward` (monotonic time
    of the last set-point let through, ``-inf`` before the first). Not thread-safe: one
    thread checks (the bridge's command thread); another may only set :attr:`active`.
    """

    def __init__(
        self,
        *,
        allow_commands: bool = False,
        silence_s: float = 2.0,
        geofence: Sequence[float] | None = None,
        geofence_margin_m: float = 20.0,
        max_rate_hz: float | None = None,
        active: str = keys.DEFAULT_ACTIVE,
        required_mode: int | None = None,
    ):
        if not (isinstance(geofence_margin_m, (int, float)) and geofence_margin_m >= 0):
            raise InputError(f"geofence_margin_m: expected a number >= 0, got {geofence_margin_m!r}")
        if max_rate_hz is not None and not (isinstance(max_rate_hz, (int, float)) and max_rate_hz > 0):
            raise InputError(f"max_rate_hz: expected None or a number > 0, got {max_rate_hz!r}")
        if not (isinstance(silence_s, (int, float)) and silence_s > 0):
            raise InputError(f"silence_s: expected a number > 0, got {silence_s!r}")
        self.allow_commands = bool(allow_commands)
        self.silence_s = float(silence_s)
        self.geofence = _geofence(geofence)
        self.geofence_margin_m = float(geofence_margin_m)
        self.max_rate_hz = None if max_rate_hz is None else float(max_rate_hz)
        self.active = active
        self.required_mode = required_mode
        self.last_forward = -math.inf

    def __repr__(self) -> str:
        return (
            f"CommandGate(allow_commands={self.allow_commands}, active={self.active!r}, silence_s={self.silence_s}, "
            f"geofence={self.geofence}, geofence_margin_m={self.geofence_margin_m}, max_rate_hz={self.max_rate_hz})"
        )

    def check_source(self, source: str) -> str | None:
        """``"inactive"`` unless ``source`` (of ``rapt/<vehicle>/command/<source>``) is :attr:`active`."""
        return None if source == self.active else INACTIVE

    def check(
        self,
        setpoint: Setpoint,
        now: float,
        position: tuple[float, float, float] | None,
        heard: float | None,
        mode: int | None = None,
    ) -> str | None:
        """Why ``setpoint`` may not go to the vehicle at ``now``, or None to forward it.

        ``position``: the last ``(north, east, at)`` in metres (local NED) and monotonic
        seconds, None when unknown. ``heard``: monotonic time of the last frame while an
        autopilot is known, None when none is. ``mode``: the autopilot's custom mode from its last
        HEARTBEAT (None: unknown). A None answer is a decision to forward: it
        starts the rate limit's next interval at ``now``, whether or not the send succeeds.
        """
        if not self.allow_commands:
            return REFUSED
        if heard is None or now - heard > self.silence_s:
            return STALE
        if self.required_mode is not None and mode != self.required_mode:
            return MODE
        if self.geofence is not None and (setpoint.vx or setpoint.vy):
            if (
                position is None
                or now - position[2] > self.silence_s
                or outward(self.geofence, self.geofence_margin_m, position[0], position[1], setpoint.vx, setpoint.vy)
            ):
                return GEOFENCE
        if self.max_rate_hz is not None:
            if now - self.last_forward < 1.0 / self.max_rate_hz:
                return RATE_LIMITED
            self.last_forward = now
        return None
