"""Read a log's Foxglove channels back, with the Python MCAP reader (checked against their schemas) and
with Foxglove's TypeScript reader (``tests/support/ts_reader``, installed from npm when missing)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import jsonschema
import pytest
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


# --------------------------------------------------------------------------- the TypeScript reader
TS_READER = Path(__file__).with_name("ts_reader")


def typescript_reader() -> Path:
    """A directory with ``read_mcap.mjs`` and Foxglove's TypeScript MCAP packages installed (``npm ci`` of
    ``tests/support/ts_reader``'s lock file, once per lock-file version, under ``~/.cache/rapt-npm`` or
    ``$RAPT_NPM_CACHE``); skips the test only when node or npm is not installed."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.skip("node and npm are needed for the TypeScript MCAP reader check")
    files = ("package.json", "package-lock.json", "read_mcap.mjs")
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
