"""Read a log's Foxglove channels back with the Python MCAP reader and check them against their schemas."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import jsonschema
from mcap.reader import make_reader

from bridge import foxglove


@dataclass
class FoxgloveChannel:
    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    schema: dict
    messages: list[dict] = field(default_factory=list)


def foxglove_channels(path: str | Path) -> dict[str, FoxgloveChannel]:
    """Every channel of the log whose schema is one of Foxglove's, with its decoded messages."""
    out: dict[str, FoxgloveChannel] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is None or not schema.name.startswith("foxglove."):
                continue
            entry = out.get(channel.topic)
            if entry is None:
                entry = out[channel.topic] = FoxgloveChannel(
                    channel.topic, schema.name, schema.encoding, channel.message_encoding, json.loads(schema.data)
                )
            entry.messages.append(json.loads(message.data))
    return out


def check_channel(channel: FoxgloveChannel) -> None:
    """The channel is JSON under Foxglove's own schema of that name, and every message validates with every
    field present (Foxglove's JSON Schemas list no ``required``; its panels expect all fields)."""
    assert channel.schema_name in foxglove.WELL_KNOWN, channel.schema_name
    assert channel.schema_encoding == "jsonschema" and channel.message_encoding == "json", channel
    assert channel.schema == foxglove.schema(channel.schema_name)
    assert channel.schema["title"] == channel.schema_name
    validator = jsonschema.Draft7Validator(channel.schema)
    for message in channel.messages:
        validator.validate(message)
        assert set(message) == set(channel.schema["properties"]), (channel.topic, sorted(message))
