"""The channels of one MCAP file being written, each registered (with its schema) on first use.

The logger and ``rapt-plan compare``'s Foxglove overlays both write messages on topics they
learn as they go; this keeps one channel per topic and one schema per name, and numbers each
channel's messages in order (the MCAP ``sequence``). The bus's own channels are JSON under
``jsonschema`` schemas; Foxglove's well-known messages are Protobuf under the schemas of
Foxglove's SDK (:mod:`bridge.foxglove`).
"""

from __future__ import annotations

import json
from typing import Any

from mcap.writer import Writer

from . import foxglove

__all__ = ["McapChannels"]

#: A channel's schema: (name, schema encoding, schema bytes).
Schema = tuple[str, str, bytes]


class McapChannels:
    """Channels and schemas of ``writer``, registered on first use."""

    def __init__(self, writer: Writer):
        self.writer = writer
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, list[int]]] = {}

    def channel(
        self, topic: str, encoding: str, schema: Schema | None, metadata: dict[str, str] | None = None
    ) -> tuple[int, list[int]]:
        """``(channel id, [next sequence number])`` of ``topic``; ``schema`` is ``(name, encoding, data)`` or
        None; ``metadata`` goes into the channel record when it is registered."""
        entry = self._channels.get(topic)
        if entry is None:
            schema_id = 0
            if schema is not None:
                name, schema_encoding, data = schema
                schema_id = self._schemas.get(name, 0)
                if not schema_id:
                    schema_id = self.writer.register_schema(name, schema_encoding, data)
                    self._schemas[name] = schema_id
            channel_id = self.writer.register_channel(topic, encoding, schema_id, metadata or {})
            entry = self._channels[topic] = (channel_id, [0])
        return entry

    def add(self, topic: str, encoding: str, schema: Schema | None, data: bytes, log_ns: int, publish_ns: int) -> None:
        """One message on ``topic`` (its channel registered if new), numbered after the channel's last."""
        channel_id, seq = self.channel(topic, encoding, schema)
        self.writer.add_message(channel_id, log_time=log_ns, data=data, publish_time=publish_ns, sequence=seq[0])
        seq[0] += 1

    def add_json(self, topic: str, schema: tuple[str, dict], message: Any, log_ns: int, publish_ns: int) -> None:
        """One JSON message (NaN refused, as JSON has none) on a ``json`` channel of ``schema`` (name, JSON
        Schema)."""
        data = json.dumps(message, allow_nan=False).encode()
        self.add(topic, "json", json_schema(*schema), data, log_ns, publish_ns)

    def add_foxglove(self, topic: str, schema_name: str, message: dict, log_ns: int, publish_ns: int) -> None:
        """One of Foxglove's well-known messages, encoded and described by Foxglove's SDK."""
        s = foxglove.schema(schema_name)
        data = foxglove.encode(schema_name, message)
        self.add(topic, foxglove.ENCODING, (s.name, s.encoding, s.data), data, log_ns, publish_ns)


def json_schema(name: str, body: dict) -> Schema:
    """A ``jsonschema`` schema record of ``body`` under ``name``."""
    return name, "jsonschema", json.dumps(body).encode()
