"""The Zenoh key expressions of one vehicle, in one place so every process agrees on them.

Everything about a vehicle lives under ``rapt/<vehicle>/``:

==========================================  ===============================================
``rapt/<v>/mavlink/<MSG_NAME>``             one decoded MAVLink message as JSON (``msg.to_dict()``,
                                            bytes base64, NaN as null) plus ``"_recv_ns"``
``rapt/<v>/mavlink/raw``                    every received MAVLink frame's bytes, in order, one
                                            reliable publisher, signature blocks left intact (and
                                            the live-virtual range's frames, see ``virtual/``)
``rapt/<v>/virtual/<MSG_NAME>``             a message the live-virtual range made up for the
                                            vehicle (virtual sonar contact, virtual fuel gauge),
                                            JSON as under ``mavlink/``; its frame is also on
                                            ``mavlink/raw`` with the attachment ``b"virtual"``
``rapt/<v>/command/<source>``               a back-seat set-point, JSON ``{"tick_ms": int|null,
                                            "vx": m/s north, "vy": m/s east, "vz": m/s down
                                            (negative rises), "yaw": rad}``
``rapt/<v>/control/active``                 the source name allowed to command (text payload;
                                            ``"autonomy"`` until someone says otherwise)
``rapt/<v>/status/<source>``                free JSON from a back-seat process (only logged); the
                                            bridge's and the logger's counters, losses included,
                                            once a second on ``status/bridge`` and ``status/logger``
``rapt/<v>/meta/<name>``                    scenario metadata JSON (mission file, scenario id,
                                            parameters, plan id); MCAP metadata in the log
``rapt/<v>/alive/<role>``                   liveliness tokens (``bridge``, ``logger``, ...)
``rapt/<v>/map/<name>``                     a GeoJSON document for the map (the scenario's mission
                                            elements and predicted track), put once at the start;
                                            logged as a ``foxglove.GeoJSON`` channel ``/map/<name>``
==========================================  ===============================================

The sources that command the vehicle (``command/<source>``, ``control/active``), named here so
every process agrees on who flies it:

=======================  ==========================================================================
``DEFAULT_ACTIVE``       ``"autonomy"``: the scenario's back-seat autonomy, active from the start
``BRINGUP_SOURCE``       ``"bringup"``: a real vehicle's bring-up, taking it down before the run
``WATCHDOG_SOURCE``      ``"watchdog"``: the watchdog, when it takes over (also its role and its
                         ``status/`` and ``alive/`` name)
``SURROGATE_SOURCE``     ``"surrogate"``: a trained surrogate flying in the autonomy's place
=======================  ==========================================================================

``<vehicle>``, ``<source>``, ``<name>`` and ``<role>`` are single key chunks: non-empty, without
``/``, ``*``, ``$``, ``?``, ``#`` or spaces. ``"*"`` is accepted where a pattern makes sense
(``command(v, "*")``, ``alive(v, "*")``).

A bad name raises the built-in ``ValueError`` (``TypeError`` for a non-str), not a
:mod:`rapt.errors` class: this module and :mod:`bridge.setpoint` are what a back-seat on
another computer imports, and :mod:`rapt.errors` would import all of :mod:`rapt` (numpy,
SciPy, scikit-learn) into it.
"""

from __future__ import annotations

import re

__all__ = [
    "PREFIX",
    "DEFAULT_VEHICLE",
    "DEFAULT_ACTIVE",
    "BRINGUP_SOURCE",
    "WATCHDOG_SOURCE",
    "SURROGATE_SOURCE",
    "telemetry",
    "raw",
    "virtual",
    "VIRTUAL_ATTACHMENT",
    "sequence_attachment",
    "attachment_sequence",
    "command",
    "active",
    "status",
    "meta",
    "alive",
    "map_document",
    "everything",
    "split",
]

PREFIX = "rapt"
DEFAULT_VEHICLE = "uuv1"
#: The source allowed to command until someone says otherwise: the scenario's autonomy.
DEFAULT_ACTIVE = "autonomy"
#: The source a real vehicle's bring-up commands under while it takes the vehicle down.
BRINGUP_SOURCE = "bringup"
#: The source the watchdog commands under when it takes over (and its status key, role and token).
WATCHDOG_SOURCE = "watchdog"
#: The source a trained surrogate of the autonomy commands under.
SURROGATE_SOURCE = "surrogate"
#: The Zenoh attachment of a frame on ``mavlink/raw`` that no vehicle sent (see :func:`virtual`).
VIRTUAL_ATTACHMENT = b"virtual"


def sequence_attachment(number: int) -> bytes:
    """The Zenoh attachment numbering a bridge publication: 8 bytes, little-endian, one counter per key.

    The logger counts the numbers it never received as lost on the bus.
    """
    return number.to_bytes(8, "little")


def attachment_sequence(attachment: bytes | None) -> int | None:
    """The number in a :func:`sequence_attachment`, None for any other attachment (``VIRTUAL_ATTACHMENT``)."""
    if attachment is None or len(attachment) != 8:
        return None
    return int.from_bytes(attachment, "little")


_CHUNK = re.compile(r"[A-Za-z0-9_.\-]+\Z")


def _chunk(value: str, argument: str, *, wildcard: bool = False) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{argument}: expected a str, got {type(value).__name__}")
    if wildcard and value == "*":
        return value
    if not _CHUNK.match(value):
        raise ValueError(f"{argument}: {value!r} is not a single key chunk (letters, digits, '_', '.', '-')")
    return value


def telemetry(vehicle: str, msg_name: str) -> str:
    """``rapt/<vehicle>/mavlink/<MSG_NAME>``: one decoded message type as JSON."""
    name = _chunk(msg_name, "msg_name", wildcard=True)
    if name == "raw":
        raise ValueError("msg_name: 'raw' is reserved for raw frames")
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/mavlink/{name}"


def raw(vehicle: str) -> str:
    """``rapt/<vehicle>/mavlink/raw``: every received frame's bytes, in order."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/mavlink/raw"


def virtual(vehicle: str, msg_name: str) -> str:
    """``rapt/<vehicle>/virtual/<MSG_NAME>``: a made-up (live-virtual) message as JSON, logged apart from real ones."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/virtual/{_chunk(msg_name, 'msg_name', wildcard=True)}"


def command(vehicle: str, source: str) -> str:
    """``rapt/<vehicle>/command/<source>``: a set-point JSON from a back-seat source."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/command/{_chunk(source, 'source', wildcard=True)}"


def active(vehicle: str) -> str:
    """``rapt/<vehicle>/control/active``: the name of the source allowed to command."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/control/active"


def status(vehicle: str, source: str) -> str:
    """``rapt/<vehicle>/status/<source>``: free JSON from a back-seat process."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/status/{_chunk(source, 'source', wildcard=True)}"


def meta(vehicle: str, name: str) -> str:
    """``rapt/<vehicle>/meta/<name>``: scenario metadata JSON."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/meta/{_chunk(name, 'name', wildcard=True)}"


def alive(vehicle: str, role: str) -> str:
    """``rapt/<vehicle>/alive/<role>``: a liveliness token."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/alive/{_chunk(role, 'role', wildcard=True)}"


def map_document(vehicle: str, name: str) -> str:
    """``rapt/<vehicle>/map/<name>``: a GeoJSON document for the map (mission elements, predicted track)."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/map/{_chunk(name, 'name', wildcard=True)}"


def everything(vehicle: str) -> str:
    """``rapt/<vehicle>/**``: all keys of one vehicle."""
    return f"{PREFIX}/{_chunk(vehicle, 'vehicle')}/**"


def split(key: str) -> tuple[str, str, str]:
    """``"rapt/uuv1/mavlink/HEARTBEAT"`` -> ``("uuv1", "mavlink", "HEARTBEAT")``.

    Raises ValueError for a key outside the scheme.
    """
    parts = str(key).split("/", 3)
    if len(parts) != 4 or parts[0] != PREFIX or not parts[1] or not parts[2] or not parts[3]:
        raise ValueError(f"key: {key!r} is not of the form {PREFIX}/<vehicle>/<kind>/<name>")
    return parts[1], parts[2], parts[3]
