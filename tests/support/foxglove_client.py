"""A Foxglove WebSocket client (subprotocol ``foxglove.sdk.v1``) as a test's eyes on a live view.

It speaks the protocol itself with ``websockets``: it reads the server's advertisements,
subscribes to every channel it is told of (or those a test names), and decodes what arrives:
JSON channels as dicts, Protobuf channels with the ``FileDescriptorSet`` the server advertised.
"""

from __future__ import annotations

import base64
import json
import struct
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from tests.support.foxglove_check import decode

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


class FoxgloveClient:
    """Connected to ``url`` until :meth:`close`; subscribes to each advertised channel ``wanted`` accepts."""

    def __init__(self, url: str, wanted: Callable[[str], bool] = lambda topic: True):
        self._connection = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=10, max_size=None)
        self.ws = self._connection.__enter__()
        self.wanted = wanted
        self.server_info: dict | None = None
        self.channels: dict[int, dict] = {}  # channel id -> advertisement
        self.messages: dict[str, list[tuple[int, Any]]] = defaultdict(list)  # topic -> [(log ns, message)]
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._read, name="foxglove-client", daemon=True)
        self._thread.start()

    @property
    def topics(self) -> dict[str, dict]:
        with self._lock:
            return {c["topic"]: c for c in self.channels.values()}

    def _read(self) -> None:
        try:
            for frame in self.ws:
                if isinstance(frame, str):
                    self._on_text(json.loads(frame))
                elif frame and frame[0] == MESSAGE_DATA:
                    self._on_data(frame)
        except ConnectionClosed:
            pass

    def _on_text(self, msg: dict) -> None:
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            subscribe = []
            with self._lock:
                for ch in msg["channels"]:
                    self.channels[ch["id"]] = ch
                    if self.wanted(ch["topic"]):
                        sub_id = len(self._subscriptions) + 1
                        self._subscriptions[sub_id] = ch["id"]
                        subscribe.append({"id": sub_id, "channelId": ch["id"]})
            if subscribe:
                self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))
        elif op == "unadvertise":
            with self._lock:
                for cid in msg["channelIds"]:
                    self.channels.pop(cid, None)

    def _on_data(self, frame: bytes) -> None:
        sub_id, log_ns = struct.unpack_from("<IQ", frame, 1)
        payload = frame[13:]
        with self._lock:
            ch = self.channels.get(self._subscriptions.get(sub_id, -1))
        if ch is None:
            return
        if ch["encoding"] == "json":
            message = json.loads(payload)
        else:
            message = decode(ch["schemaName"], base64.b64decode(ch["schema"]), bytes(payload))
        with self._lock:
            self.messages[ch["topic"]].append((log_ns, message))

    def subscribed(self, topic: str) -> bool:
        with self._lock:
            return any(self.channels.get(cid, {}).get("topic") == topic for cid in self._subscriptions.values())

    def received(self, topic: str) -> list[Any]:
        with self._lock:
            return [m for _, m in self.messages.get(topic, [])]

    def wait_for(self, test: Callable[[], Any], timeout: float = 20.0, what: str = "") -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = test()
            if value:
                return value
            time.sleep(0.05)
        raise AssertionError(f"foxglove client: no {what or 'match'} within {timeout} s; topics {sorted(self.topics)}")

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._connection.__exit__(None, None, None)
            self._thread.join(timeout=5)

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
