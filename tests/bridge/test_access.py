"""The secure bus on loopback: who may join the hub, who may put what, and what reaches the vehicle."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
import zenoh  # noqa: E402

import sim.uuv  # noqa: E402
from bridge import keys  # noqa: E402
from bridge.access import access_rules, permissions_table, role_permissions  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.range_keys import make_range_keys, role_config  # noqa: E402
from bridge.session import zenoh_config  # noqa: E402
from bridge.setpoint import Setpoint  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402

V = "uuv1"
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: The set-points of the autonomy, the rogue and the logger, told apart by their yaw.
SETPOINT, ROGUE, LOGGER = (Setpoint(0.3, 0.0, 0.0, yaw).to_json().decode() for yaw in (0.0, 1.0, 2.0))


@pytest.fixture
def range_dir(tmp_path):
    """A range's keys with a genuine second autonomy, ``rogue``, and a hub on a free loopback port."""
    return make_range_keys(tmp_path / "keys", V, hub=f"tls/127.0.0.1:{free_port()}", autonomies=("autonomy", "rogue"))


def _open(config: zenoh.Config, timeout_s: float = 5.0) -> zenoh.Session:
    if json.loads(config.get_json("mode")) == "client":
        config.insert_json5("connect/timeout_ms", str(int(timeout_s * 1000)))
    return zenoh.open(config)


def _hub_endpoint(range_dir) -> str:
    (endpoint,) = json.loads(role_config(range_dir, "bridge").get_json("listen/endpoints"))
    return endpoint


@contextlib.contextmanager
def sessions(range_dir, *roles: str):
    """The hub (the bridge role) and a client session per role; all closed on exit."""
    opened = [_open(role_config(range_dir, "bridge"))]
    try:
        opened += [_open(role_config(range_dir, role)) for role in roles]
        yield opened
    finally:
        for session in reversed(opened):
            session.close()


class Heard:
    """(key, payload) of every sample a session's subscriber receives on ``rapt/<v>/**``."""

    def __init__(self, session: zenoh.Session, key: str | None = keys.everything(V)):
        self.samples: list[tuple[str, str]] = []
        self._lock = threading.Lock()
        self.sub = None if key is None else session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample) -> None:
        with self._lock:
            self.samples.append((str(sample.key_expr), sample.payload.to_string()))

    def keys(self) -> set[tuple[str, str]]:
        with self._lock:
            return set(self.samples)


def _wait_for_routes(hub, *hearing: Heard) -> None:
    """Put on ``mavlink/HEARTBEAT`` from the hub until each subscriber has heard it (declarations have arrived)."""
    key = keys.telemetry(V, "HEARTBEAT")

    def heard() -> bool:
        hub.put(key, "ready")
        return all((key, "ready") in h.keys() for h in hearing)

    wait_until(heard, what="the clients' subscriptions at the hub")


def test_the_rules_deny_by_default_and_grant_each_role_only_its_own_keys():
    rules = access_rules(V, ["autonomy", "rogue"])
    assert rules["enabled"] is True and rules["default_permission"] == "deny"
    assert {s["id"]: s["cert_common_names"] for s in rules["subjects"]} == {
        r: [r] for r in ("autonomy", "rogue", "watchdog", "logger", "operator")
    }
    assert all(r["permission"] == "allow" for r in rules["rules"])
    assert role_permissions(V, "rogue", autonomy=True)["put"] == [
        "rapt/uuv1/command/rogue",
        "rapt/uuv1/status/rogue",
        "rapt/uuv1/map/scenario",
    ]
    assert role_permissions(V, "logger")["put"] == ["rapt/uuv1/status/logger"]
    for role in ("watchdog", "operator"):
        assert keys.active(V) in role_permissions(V, role)["put"]
    with pytest.raises(ValueError, match="vehicle"):
        access_rules("a/b")


def test_a_client_without_a_certificate_or_with_another_ranges_cannot_join(range_dir, tmp_path):
    hub_endpoint = _hub_endpoint(range_dir)
    other = make_range_keys(tmp_path / "other", V, hub=hub_endpoint)
    no_certificate = zenoh_config(connect=[hub_endpoint], connect_timeout=0.5)
    no_certificate.insert_json5("transport/link/tls/root_ca_certificate", f'"{range_dir / "ca.pem"}"')
    foreign = role_config(other, "autonomy")  # a certificate of another CA, trusting our hub's
    foreign.insert_json5("transport/link/tls/root_ca_certificate", f'"{range_dir / "ca.pem"}"')
    plain_tcp = zenoh_config(connect=[hub_endpoint.replace("tls/", "tcp/")], connect_timeout=0.5)
    with sessions(range_dir) as (hub,):
        heard = Heard(hub)
        for config in (no_certificate, foreign, plain_tcp):
            started = time.monotonic()
            with pytest.raises(zenoh.ZError, match="Unable to connect"):
                _open(config, timeout_s=0.5).close()
            assert time.monotonic() - started < 2.0
        with _open(role_config(range_dir, "logger")) as genuine:  # while the range's own certificate joins
            genuine.put(keys.status(V, "logger"), "in")
            wait_until(lambda: heard.keys() == {(keys.status(V, "logger"), "in")}, what="the genuine client's put")


def test_each_role_puts_only_its_own_keys_and_the_logger_hears_them_all(range_dir):
    command, active, status = (lambda s: keys.command(V, s)), keys.active(V), (lambda s: keys.status(V, s))
    # per role: (denied, allowed) puts; denied ones first, so once the allowed ones arrived the others had their chance
    attempts = {
        "autonomy": (
            [active, command("rogue")],
            [command("autonomy"), status("autonomy"), keys.map_document(V, "scenario")],
        ),
        "rogue": ([command("autonomy"), active, status("autonomy")], [command("rogue")]),
        "logger": (
            [command("logger"), command("autonomy"), active, keys.telemetry(V, "HEARTBEAT")],
            [status("logger")],
        ),
        "watchdog": ([command("autonomy")], [active, command("watchdog")]),
        "operator": ([command("autonomy"), keys.raw(V)], [active]),
    }
    with sessions(range_dir, *attempts) as (hub, *clients):
        at_hub, by = Heard(hub), dict(zip(attempts, clients))
        logger = Heard(by["logger"])
        _wait_for_routes(hub, logger)
        # liveliness: each declares its own token; the rogue cannot pass for the bridge
        tokens = [by[r].liveliness().declare_token(keys.alive(V, r)) for r in ("autonomy", "logger")]
        tokens.append(by["rogue"].liveliness().declare_token(keys.alive(V, "bridge")))
        alive = Heard(hub, key=None)
        alive.sub = hub.liveliness().declare_subscriber(keys.alive(V, "*"), alive._on_sample, history=True)
        seen_by_autonomy = Heard(by["autonomy"], key=None)
        seen_by_autonomy.sub = (
            by["autonomy"]
            .liveliness()
            .declare_subscriber(keys.alive(V, "logger"), seen_by_autonomy._on_sample, history=True)
        )
        for role, (denied, allowed) in attempts.items():
            for key in denied + allowed:
                by[role].put(key, role)
        expected = {(key, role) for role, (_, allowed) in attempts.items() for key in allowed}
        wait_until(lambda: expected <= at_hub.keys(), what="every allowed put at the hub")
        time.sleep(0.2)
        ready = (keys.telemetry(V, "HEARTBEAT"), "ready")
        assert at_hub.keys() - {ready} == expected
        # the logger hears everything that reached the hub, from every client (its own puts it hears locally)
        assert expected <= logger.keys()
        assert logger.keys() - expected - {ready} == {(k, "logger") for k in attempts["logger"][0]}
        wait_until(lambda: seen_by_autonomy.keys(), what="the logger's token at the autonomy")
        assert {k for k, _ in alive.keys()} == {keys.alive(V, "autonomy"), keys.alive(V, "logger")}
        for token in tokens:
            token.undeclare()


def test_the_vehicle_gets_the_authorised_autonomys_setpoints_and_none_of_the_rogues(range_dir):
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(3).random((20, m.dim))
    u = X[np.flatnonzero(make_scenarios(m, X).valid)[0]]
    port = free_port(socket.SOCK_DGRAM)
    fs = FrontSeat(m, u, f"udpin:127.0.0.1:{port}", lockstep=False, speedup=10.0)
    fs_thread = threading.Thread(target=fs.serve, name="frontseat", daemon=True)
    fs_thread.start()
    try:
        with sessions(range_dir, "autonomy", "rogue", "logger") as (hub, autonomy, rogue, logger_session):
            logger = Heard(logger_session)
            with MavlinkBridge(f"udpout:127.0.0.1:{port}", hub, vehicle=V, allow_commands=True) as bridge:
                wait_until(lambda: bridge.target is not None, what="the vehicle's heartbeat")
                assert bridge.set_mode("GUIDED") == 0 and bridge.arm(True) == 0
                wait_until(lambda: any(k == keys.telemetry(V, "HEARTBEAT") for k, _ in logger.keys()), what="telemetry")
                rogue.put(keys.active(V), "rogue")  # denied: the bridge still takes the autonomy's
                logger_session.put(keys.active(V), "logger")  # denied
                rogue.put(keys.command(V, "autonomy"), ROGUE)  # denied: not its name
                logger_session.put(keys.command(V, "autonomy"), LOGGER)  # denied
                for _ in range(3):
                    rogue.put(keys.command(V, "rogue"), ROGUE)  # its own key: reaches the bridge, inactive
                wait_until(lambda: bridge.stats["commands_in"] == 3, what="the rogue's own set-points at the bridge")
                time.sleep(0.2)
                assert bridge.stats["commands_inactive"] == 3 and bridge.active == "autonomy"
                assert fs.stats.setpoints == 0 and bridge.stats["commands_forwarded"] == 0
                for _ in range(5):
                    autonomy.put(keys.command(V, "autonomy"), SETPOINT)
                wait_until(lambda: fs.stats.setpoints == 5, what="the autonomy's set-points on the vehicle")
                time.sleep(0.2)
                assert fs.stats.setpoints == 5 and bridge.stats["commands_forwarded"] == 5
                assert bridge.stats["commands_in"] == 8
            # the logger heard what passed the hub, and none of the rogue's claims
            heard = logger.samples
            assert heard.count((keys.command(V, "autonomy"), SETPOINT)) == 5
            assert heard.count((keys.command(V, "rogue"), ROGUE)) == 3
            assert (keys.command(V, "autonomy"), ROGUE) not in heard and (keys.active(V), "rogue") not in heard
    finally:
        fs.stop()
        fs_thread.join(timeout=5)
        fs.close()


def test_the_administrators_page_shows_the_rules_as_they_are():
    page = (Path(__file__).resolve().parents[2] / "docs" / "range-network.md").read_text()
    assert permissions_table(V) in page
