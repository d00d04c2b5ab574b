"""The Zenoh bus linking a MAVLink front-seat, back-seat autonomy processes and the MCAP logger.

Never imports :mod:`sim`; the planner wires the autonomy to the bus.

Modules: :mod:`bridge.keys` (the key scheme), :mod:`bridge.session` (loopback Zenoh
sessions), :mod:`bridge.setpoint` (the back-seat set-point), :mod:`bridge.frames` (MAVLink
frame handling), :mod:`bridge.mission_upload` (the mission upload protocol, no I/O),
:mod:`bridge.command_gate` (:class:`CommandGate`, the bridge's safety
gates), :mod:`bridge.service` (the start/close life cycle), the bridge's three layers
:mod:`bridge.link` (:class:`MavlinkLink`, the MAVLink connection), :mod:`bridge.vehicle_commands`
(:class:`VehicleCommands`, COMMAND_LONG, modes, mission upload) and :mod:`bridge.relay`
(:class:`BusRelay`, to and from the bus through the gate), composed by :mod:`bridge.mavlink_bridge`
(:class:`MavlinkBridge`), and :mod:`bridge.logger` (:class:`McapLogger`). The names below are
imported on first use, so ``import bridge.keys`` stays cheap for a back-seat process.
"""

from importlib import import_module

_EXPORTS = {
    "CommandGate": "bridge.command_gate",
    "MavlinkBridge": "bridge.mavlink_bridge",
    "McapLogger": "bridge.logger",
    "MissionItem": "bridge.mission_upload",
    "read_log": "bridge.logger",
    "read_metadata": "bridge.logger",
    "Setpoint": "bridge.setpoint",
    "open_session": "bridge.session",
    "zenoh_config": "bridge.session",
}

__all__ = [*_EXPORTS, "keys"]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    if name == "keys":
        return import_module("bridge.keys")
    raise AttributeError(f"module 'bridge' has no attribute {name!r}")
