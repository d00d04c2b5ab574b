"""ArduSub's parameters as a ground station sees them, and the PARAM_* protocol's rules for them.

A ground station downloads the parameter list on connect (QGroundControl will not finish
connecting without it) and may change any of them.  :data:`ARDUSUB_PARAMETERS` is the
subset a ground station reads on connect and our vehicle model maps to, with the names,
values and types ArduSub SITL reports at boot (:data:`FIRMWARE`, read off it with
pymavlink), in the firmware's own order.  Index i of this table is PARAM_VALUE's
``param_index`` i and ``param_count`` is its length (the firmware has 1,386).

What :meth:`ParameterTable.set` does is what ArduPilot's PARAM_SET does (GCS_Param.cpp,
checked on SITL): an unknown name, NaN or infinity changes nothing and gets no answer; a
float is stored as a 32-bit float with no range check (FS_GCS_TIMEOUT 1e6 is kept); an
integer parameter gets the value plus 0.01 towards its sign, clamped to its type's range
and truncated (1.7 -> 1, 1000 into an INT8 -> 127).  Values hold for the run.

What acts on the simulated vehicle (the bare front-seat, :mod:`sim.uuv.ardusub.bare`):

- ``FS_GCS_ENABLE`` (0 = off) and ``FS_GCS_TIMEOUT`` (s): the ground-station failsafe that
  disarms once MAV_GCS_SYSID's heartbeat is missing that long (``gcs_failsafe_s``).
- ``MAV_GCS_SYSID``: whose heartbeat that failsafe watches.
- ``WPNAV_SPEED`` (cm/s): the fastest a position target is approached (set at start from
  the mission's cruise speed: our vehicle is not a BlueROV2).
- ``BATT_CAPACITY`` (mAh): BATTERY_STATUS / SYS_STATUS remaining percent is
  ``1 - consumed / capacity`` (set at start from the mission's battery Wh at 14.8 V).
- ``MAV1_*`` (Hz): the stream-group rates of the link (:mod:`sim.uuv.ardusub.streams`);
  REQUEST_DATA_STREAM writes them, as ArduPilot does.

The others are reported and stored but change nothing (e.g. FENCE_ENABLE 0: there is no
fence; FRAME_CONFIG, ARMING_CHECK).  The lock-step front-seat answers the same protocol;
its vehicle flies the back-seat's velocity set-points at the lock-step's pace and keeps the
scenario's battery and failsafe, so there only the stream rates are read back.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ARDUSUB_PARAMETERS", "FIRMWARE", "ParameterTable", "STREAM_PARAMETERS"]

#: The firmware the table was read from (ArduSub SITL, ``--model vectored``, sub.parm defaults).
FIRMWARE = "ArduSub V4.7.0-dev (2598e9d4)"

INT8, INT16, INT32, REAL32 = 2, 4, 6, 9  # MAV_PARAM_TYPE
_LIMITS = {INT8: (-128, 127), INT16: (-32768, 32767), INT32: (-(2**31), 2**31 - 1)}

#: (name, value, MAV_PARAM_TYPE) in the firmware's order, as SITL reports them at boot.
ARDUSUB_PARAMETERS: tuple[tuple[str, float, int], ...] = (
    ("SURFACE_DEPTH", -10.0, REAL32),
    ("FORMAT_VERSION", 1, INT16),
    ("FS_GCS_ENABLE", 2, INT8),
    ("FS_GCS_TIMEOUT", 5.0, REAL32),
    ("FS_LEAK_ENABLE", 1, INT8),
    ("FS_PRESS_ENABLE", 0, INT8),
    ("FS_TEMP_ENABLE", 0, INT8),
    ("FS_THR_ENABLE", 0, INT8),
    ("FS_THR_VALUE", 975, INT16),
    ("FS_PRESS_MAX", 105000, INT32),
    ("FS_TEMP_MAX", 62, INT8),
    ("FS_TERRAIN_ENAB", 0, INT8),
    ("FS_PILOT_INPUT", 2, INT8),
    ("FS_PILOT_TIMEOUT", 3.0, REAL32),
    ("WP_YAW_BEHAVIOR", 4, INT8),
    ("PILOT_SPEED_UP", 200, INT16),
    ("PILOT_SPEED_DN", 0, INT16),
    ("PILOT_SPEED", 200, INT16),
    ("FS_EKF_ACTION", 0, INT8),
    ("FS_EKF_THRESH", 0.8, REAL32),
    ("FS_CRASH_CHECK", 0, INT8),
    ("FRAME_CONFIG", 1, INT8),
    ("RC_SPEED", 200, INT16),
    ("WPNAV_SPEED", 100.0, REAL32),
    ("WPNAV_RADIUS", 200.0, REAL32),
    ("WPNAV_SPEED_UP", 250.0, REAL32),
    ("WPNAV_SPEED_DN", 150.0, REAL32),
    ("WPNAV_ACCEL", 250.0, REAL32),
    ("AHRS_EKF_TYPE", 3, INT8),
    ("BATT_MONITOR", 4, INT8),
    ("BATT_CAPACITY", 3300, INT32),
    ("BATT_LOW_TIMER", 10, INT8),
    ("BATT_FS_VOLTSRC", 0, INT8),
    ("BATT_LOW_VOLT", 0.0, REAL32),
    ("BATT_LOW_MAH", 0.0, REAL32),
    ("BATT_CRT_VOLT", 0.0, REAL32),
    ("BATT_CRT_MAH", 0.0, REAL32),
    ("BATT_FS_LOW_ACT", 0, INT8),
    ("BATT_FS_CRT_ACT", 0, INT8),
    ("BATT_ARM_VOLT", 0.0, REAL32),
    ("BATT_ARM_MAH", 0, INT32),
    ("ARMING_CHECK", 448, INT32),
    ("GPS1_TYPE", 1, INT8),
    ("EK3_SRC1_POSXY", 3, INT8),
    ("EK3_SRC1_VELXY", 3, INT8),
    ("EK3_SRC1_POSZ", 1, INT8),
    ("EK3_SRC1_VELZ", 0, INT8),
    ("EK3_SRC1_YAW", 1, INT8),
    ("FENCE_ENABLE", 0, INT8),
    ("FENCE_TYPE", 7, INT8),
    ("FENCE_ACTION", 1, INT8),
    ("MAV_SYSID", 1, INT16),
    ("MAV_GCS_SYSID", 255, INT16),
    ("MAV1_RAW_SENS", 2, INT16),
    ("MAV1_EXT_STAT", 2, INT16),
    ("MAV1_RC_CHAN", 2, INT16),
    ("MAV1_RAW_CTRL", 0, INT16),
    ("MAV1_POSITION", 3, INT16),
    ("MAV1_EXTRA1", 10, INT16),
    ("MAV1_EXTRA2", 10, INT16),
    ("MAV1_EXTRA3", 3, INT16),
    ("MAV1_PARAMS", 0, INT16),
    ("MAV1_ADSB", 0, INT16),
    ("MAV1_OPTIONS", 0, INT16),
)

#: The link's stream-rate parameter of each MAV_DATA_STREAM group (ArduPilot's MAVn_*; SERIAL0 is MAV1).
STREAM_PARAMETERS: dict[int, str] = {
    1: "MAV1_RAW_SENS",
    2: "MAV1_EXT_STAT",
    3: "MAV1_RC_CHAN",
    4: "MAV1_RAW_CTRL",
    6: "MAV1_POSITION",
    10: "MAV1_EXTRA1",
    11: "MAV1_EXTRA2",
    12: "MAV1_EXTRA3",
}


class ParameterTable:
    """The vehicle's parameters for one run: ArduSub's defaults, then whatever was set."""

    def __init__(self, overrides: dict[str, float] | None = None):
        self.names = [name for name, _, _ in ARDUSUB_PARAMETERS]
        self.types = {name: kind for name, _, kind in ARDUSUB_PARAMETERS}
        self.values = {name: value for name, value, _ in ARDUSUB_PARAMETERS}
        self._index = {name: i for i, name in enumerate(self.names)}
        for name, value in (overrides or {}).items():
            if self.set(name, value) is None:
                raise KeyError(name)

    def __len__(self) -> int:
        return len(self.names)

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def index(self, name: str) -> int:
        return self._index[name]

    def at(self, index: int) -> str | None:
        """The name at ``index``, or None (the firmware answers nothing then)."""
        return self.names[index] if 0 <= index < len(self.names) else None

    def set(self, name: str, value: float) -> float | None:
        """Store ``value`` as ArduPilot does; the stored value, or None when nothing changed (no answer)."""
        if name not in self._index or not math.isfinite(value):
            return None
        kind = self.types[name]
        if kind == REAL32:
            stored = float(np.float32(value))
        else:
            low, high = _LIMITS[kind]
            stored = float(math.trunc(min(max(value + math.copysign(0.01, value), low), high)))
        self.values[name] = stored
        return stored

    # -- what the vehicle model reads ----------------------------------------------------
    def gcs_failsafe_s(self) -> float | None:
        """Seconds without the ground station's heartbeat before disarming; None when off."""
        return None if self["FS_GCS_ENABLE"] == 0 else self["FS_GCS_TIMEOUT"]

    def wpnav_speed_ms(self) -> float:
        return self["WPNAV_SPEED"] / 100.0

    def stream_hz(self, group: int) -> float:
        name = STREAM_PARAMETERS.get(group)
        return 0.0 if name is None else self[name]
