"""Read a log's Foxglove channels back, with the Python MCAP reader (decoded with the Protobuf descriptors the
log itself carries) and with Foxglove's TypeScript reader (``tests/support/ts_reader``, installed from npm when
missing)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from bridge import foxglove


@dataclass
class FoxgloveChannel:
    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    schema: bytes
    messages: list[dict] = field(default_factory=list)


@cache
def message_class(name: str, descriptor_set: bytes) -> Any:
    """The Protobuf message class ``name`` of a schema's ``FileDescriptorSet`` (as a reader that knows only
    the log would build it)."""
    files = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def as_dict(message: Any) -> dict:
    """A decoded Protobuf message as Foxglove's field names and values: nested messages as dicts (an
    unset one None), repeated fields as lists, enums as numbers, timestamps as ``{"sec", "nsec"}``."""
    if message.DESCRIPTOR.full_name == "google.protobuf.Timestamp":
        return {"sec": int(message.seconds), "nsec": int(message.nanos)}
    out: dict = {}
    for f in message.DESCRIPTOR.fields:
        value = getattr(message, f.name)
        if f.message_type is not None:
            if f.is_repeated:
                out[f.name] = [as_dict(v) for v in value]
            else:
                out[f.name] = as_dict(value) if message.HasField(f.name) else None
        elif f.is_repeated:
            out[f.name] = list(value)
        elif f.has_presence and not message.HasField(f.name):
            out[f.name] = None
        else:
            out[f.name] = value
    return out


def decode(schema_name: str, descriptor_set: bytes, data: bytes) -> dict:
    return as_dict(message_class(schema_name, descriptor_set).FromString(data))


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
                    channel.topic, schema.name, schema.encoding, channel.message_encoding, bytes(schema.data)
                )
            entry.messages.append(decode(schema.name, bytes(schema.data), message.data))
    return out


#: Fields of Foxglove's schemas that the project does not fill (later additions to a schema, all optional).
UNFILLED = {"heading", "velocity", "color", "metadata"}


def check_channel(channel: FoxgloveChannel) -> None:
    """The channel is Protobuf under the Foxglove SDK's own schema of that name, and every message carries
    every field the project fills (Foxglove's panels expect them all)."""
    assert channel.schema_name in foxglove.WELL_KNOWN, channel.schema_name
    assert channel.schema_encoding == "protobuf" and channel.message_encoding == "protobuf", channel
    assert channel.schema == foxglove.schema(channel.schema_name).data
    fields = {f.name for f in message_class(channel.schema_name, channel.schema).DESCRIPTOR.fields} - UNFILLED
    for message in channel.messages:
        assert all(message[k] is not None for k in fields if k in message), (channel.topic, message)
        assert fields <= set(message), (channel.topic, sorted(message))


# --------------------------------------------------------------------------- the TypeScript reader
TS_READER = Path(__file__).with_name("ts_reader")


def typescript_reader() -> Path:
    """A directory with ``read_mcap.mjs`` and Foxglove's TypeScript MCAP packages installed (``npm ci`` of
    ``tests/support/ts_reader``'s lock file, once per lock-file version, under ``~/.cache/rapt-npm`` or
    ``$RAPT_NPM_CACHE``); skips the test only when node or npm is not installed."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.skip("node and npm are needed for the TypeScript MCAP reader check")
    files = ("package.json", "package-lock.json", "read_mcap.mjs", "live_client.mjs")
    digest = hashlib.sha256(b"".join((TS_READER / n).read_bytes() for n in files)).hexdigest()[:16]
    root = Path(os.environ.get("RAPT_NPM_CACHE", Path.home() / ".cache" / "rapt-npm"))
    target = root / digest
    if not (target / "node_modules" / "@mcap" / "support").is_dir():
        root.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=root, prefix="install-"))
        for n in files:
            shutil.copy(TS_READER / n, staging / n)
        done = subprocess.run(
            ["npm", "ci", "--ignore-scripts", "--no-audit", "--no-fund"],
            cwd=staging,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, f"npm ci failed: {done.stderr[-2000:]}"
        try:
            staging.rename(target)  # atomic: a concurrent installer's copy is as good
        except OSError:
            shutil.rmtree(staging, ignore_errors=True)
    return target


def read_with_typescript(path: str | Path, *decode: str) -> dict:
    """``read_mcap.mjs``'s report of ``path``: channels (schema, encodings, message count), the first message
    of each topic in ``decode``, and the summary's message count."""
    reader = typescript_reader()
    done = subprocess.run(
        ["node", str(reader / "read_mcap.mjs"), str(path), *decode], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def watch_with_typescript(url: str, seconds: float = 120.0) -> subprocess.Popen:
    """``live_client.mjs`` watching the live view at ``url`` (it retries until the server is up); its report
    comes on stdout when the server closes (:func:`typescript_report`)."""
    reader = typescript_reader()
    return subprocess.Popen(
        ["node", str(reader / "live_client.mjs"), url, str(seconds)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def typescript_report(watcher: subprocess.Popen, timeout: float = 60.0) -> dict:
    """What :func:`watch_with_typescript`'s client saw: channels (schema, encodings, count), first and last
    message per topic, the subprotocol."""
    try:
        out, errors = watcher.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        watcher.kill()
        out, errors = watcher.communicate()
    assert watcher.returncode == 0, errors
    return json.loads(out)
