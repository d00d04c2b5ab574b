"""The hub's link for a live view: a Unix socket over which the hub sends telemetry only as fast as a screen shows it.

The live view (:mod:`bridge.live_view`) shows each telemetry message's latest sample
:data:`~bridge.live_view.TELEMETRY_HZ` times a second, yet over an ordinary link the hub routes
it every sample the vehicle sends, and that routing runs on the hub, the process that answers
the vehicle with its set-points. :class:`ViewLink` gives the hub a second listening endpoint, a
Unix socket, with Zenoh's egress downsampling on that link protocol only: each telemetry key
the view reads, and the active autonomy's status (put at every decision), leave on it at most
``TELEMETRY_HZ`` times a second, each key on its own. Every other process, joined over TCP,
still gets every sample; events, maps and the other statuses pass the view's link untouched.
A vehicle reporting slower than that loses nothing on it.

Loopback bus only: on the range's secure bus every role joins over mutual TLS, and a socket file
beside it would be a way round the access rules.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import zenoh

from . import keys
from .live_view import TELEMETRY, TELEMETRY_HZ

__all__ = ["LINK_PROTOCOL", "ViewLink"]

#: The link protocol the view joins over, and the only one the downsampling applies to.
LINK_PROTOCOL = "unixsock-stream"


class ViewLink:
    """A Unix-socket endpoint for a live view of ``vehicle``, added to a hub's ``zenoh.Config`` before it opens.

    :meth:`add_to` makes the config listen on it with the downsampling rules; :attr:`endpoint` is
    what the view connects to. The socket lives in a directory of its own, removed by :meth:`close`.
    """

    def __init__(self, vehicle: str = keys.DEFAULT_VEHICLE, hz: float = TELEMETRY_HZ):
        keys.everything(vehicle)  # validates the name
        self.vehicle, self.hz = vehicle, float(hz)
        self._dir: tempfile.TemporaryDirectory | None = tempfile.TemporaryDirectory(prefix="rapt-view-")
        self.endpoint = f"{LINK_PROTOCOL}/{Path(self._dir.name) / 'view.sock'}"

    def rules(self) -> list[dict]:
        """Zenoh's ``downsampling`` entry: one rule per thinned key (a rule's rate is shared by what it matches)."""
        thinned = [keys.telemetry(self.vehicle, m) for m in TELEMETRY] + [
            keys.status(self.vehicle, keys.DEFAULT_ACTIVE)
        ]
        rules = [{"key_expr": key, "freq": self.hz} for key in thinned]
        return [
            {
                "id": "rapt-live-view",
                "link_protocols": [LINK_PROTOCOL],
                "flows": ["egress"],
                "messages": ["put"],
                "rules": rules,
            }
        ]

    def add_to(self, config: zenoh.Config) -> zenoh.Config:
        """``config`` listening on the view's endpoint too, its egress on that link downsampled; returned."""
        listen = json.loads(config.get_json("listen/endpoints") or "[]")
        if isinstance(listen, dict):  # a mode-keyed list from a config file
            mode = json.loads(config.get_json("mode") or '"peer"')
            listen = {**listen, mode: [*listen.get(mode, []), self.endpoint]}
        else:
            listen = [*listen, self.endpoint]
        config.insert_json5("listen/endpoints", json.dumps(listen))
        existing = json.loads(config.get_json("downsampling") or "[]")
        config.insert_json5("downsampling", json.dumps([*existing, *self.rules()]))
        return config

    def close(self) -> None:
        """Remove the socket's directory (after the hub's session has closed). Idempotent."""
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None

    def __enter__(self) -> ViewLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
