"""Nothing is lost silently: a forced loss is counted at the bridge, on the bus and in the log; load loses nothing."""

from __future__ import annotations

import json
import os
import socket
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.logger import LOSSES_METADATA, RAW_TOPIC, McapLogger, read_log, read_metadata  # noqa: E402
from bridge.loss import PublicationGaps, SequenceGaps  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.session import open_session  # noqa: E402
from tests.support.bridge_rig import VEHICLE, Collector, bus, wait_for_subscriber  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402


# --------------------------------------------------------------------------- counting, pure
def test_sequence_gaps_count_per_sender_modulo_256():
    gaps = SequenceGaps()
    for seq in [250, 251, 254, 255, 0, 3]:  # 252, 253 and 1, 2 never come (across the wrap)
        gaps.see(1, 1, seq)
    for seq in [7, 8, 9]:  # another component on the same link: its own counter, no loss
        gaps.see(1, 100, seq)
    assert gaps.lost == 4 and gaps.as_dict()["by_source"] == {"1/1": 4, "1/100": 0}


def test_a_late_frame_is_taken_back_and_a_duplicate_is_not_a_loss():
    gaps = SequenceGaps()
    for seq in [10, 11, 13, 12, 13, 14]:  # 12 comes after 13; 13 comes twice
        gaps.see(2, 1, seq)
    assert (gaps.lost, gaps.late, gaps.duplicates) == (0, 1, 1)
    gaps.see(2, 1, 200)  # a burst of 185 lost: more than half the counter, still a loss
    assert gaps.lost == 185


def test_publication_gaps_start_at_the_first_number_and_survive_a_restart():
    gaps = PublicationGaps()
    for key, number in [("a", 40), ("a", 41), ("a", 44), ("b", 0), ("a", 0), ("a", 1)]:
        gaps.see(key, number)
    assert (gaps.lost, gaps.by_key, gaps.restarts) == (2, {"a": 2}, 1)


# --------------------------------------------------------------------------- on loopback
def _sender(port: int, system: int, component: int):
    return mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=system, source_component=component, dialect="ardupilotmega"
    )


@pytest.mark.integration
def test_a_sender_skipping_sequence_numbers_is_reported_at_the_bridge_on_the_bus_and_in_the_log(tmp_path):
    path = tmp_path / "loss.mcap"
    port = free_port(socket.SOCK_DGRAM)
    autopilot, camera = _sender(port, 1, 1), _sender(port, 1, 100)
    with bus() as (hub, client, endpoint):
        status = Collector(client, keys.status(VEHICLE, "bridge"))
        logger_session = open_session(connect=[endpoint])
        try:
            logger = McapLogger(path, logger_session, vehicle=VEHICLE, flush_interval_s=0.2).start()
            try:
                wait_for_subscriber(hub, keys.status(VEHICLE, "bridge"))  # the logger sees the bridge's first status
                with MavlinkBridge(f"udpin:127.0.0.1:{port}", hub, vehicle=VEHICLE, status_interval_s=0.2) as bridge:
                    # the logger counts from the first status it sees: let that be one from before the losses
                    wait_until(
                        lambda: logger.losses()["link_lost"] == 0, what="the bridge's first status at the logger"
                    )
                    for k in range(60):
                        if k in (20, 40):  # skip 3, then 4 sequence numbers
                            autopilot.mav.seq = (autopilot.mav.seq + 3 + (k == 40)) % 256
                        autopilot.mav.attitude_send(k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                        if k == 30:
                            camera.mav.seq = (camera.mav.seq + 5) % 256
                        camera.mav.named_value_int_send(k, b"shot", k)
                        time.sleep(0.001)
                    wait_until(lambda: bridge.stats["frames_in"] == 120, what="every frame sent")
                    # a bus publisher that skips two of its numbers: the logger counts them lost on the bus
                    probe = client.declare_publisher(keys.telemetry(VEHICLE, "PROBE"))
                    wait_for_subscriber(client, keys.telemetry(VEHICLE, "PROBE"))
                    for number in (0, 1, 4):
                        probe.put(b"{}", attachment=keys.sequence_attachment(number))
                    probe.undeclare()
                    assert bridge.stats["link_lost"] == 12 and bridge.link_lost_by_source == {"1/1": 7, "1/100": 5}
                    wait_until(
                        lambda: [s["link_lost"] for s in status.json(keys.status(VEHICLE, "bridge"))][-1:] == [12],
                        what="the loss on status/bridge",
                    )
                wait_until(lambda: logger.losses()["link_lost"] == 12, what="the bridge's last status at the logger")
                wait_until(lambda: logger.losses()["bus_lost"] == 2, what="the probe's gap at the logger")
            finally:
                logger.close()
        finally:
            logger_session.close()
            status.close()
    autopilot.close()
    camera.close()

    losses = read_metadata(path)[LOSSES_METADATA]
    assert losses["link_lost"] == "12" and json.loads(losses["link_lost_by_source"]) == {"1/1": 7, "1/100": 5}
    assert losses["bus_lost"] == "2" and json.loads(losses["bus_lost_by_key"]) == {keys.telemetry(VEHICLE, "PROBE"): 2}
    assert losses["write_errors"] == "0" and losses["total"] == "14" and losses["kernel_dropped"] == "0"
    assert sum(1 for topic, _, _ in read_log(path) if topic == RAW_TOPIC) == 120


@pytest.mark.integration
def test_sustained_load_reaches_the_log_whole(tmp_path):
    """2 s at 3,000 frames/s through the bridge into a logger on another session: sent == logged, no loss anywhere."""
    path = tmp_path / "load.mcap"
    port = free_port(socket.SOCK_DGRAM)
    vehicle = _sender(port, 1, 1)
    rate, seconds = 3000, 2.0
    with bus() as (hub, client, endpoint):
        logger_session = open_session(connect=[endpoint])
        try:
            with McapLogger(path, logger_session, vehicle=VEHICLE) as logger:
                wait_for_subscriber(hub, keys.raw(VEHICLE))
                with MavlinkBridge(f"udpin:127.0.0.1:{port}", hub, vehicle=VEHICLE) as bridge:
                    sent, start = 0, time.perf_counter()
                    while (now := time.perf_counter() - start) < seconds:
                        while sent < int(now * rate):
                            vehicle.mav.attitude_send(sent, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
                            sent += 1
                        time.sleep(0.0005)
                    wait_until(lambda: bridge.stats["frames_in"] >= sent, timeout=10, what="every frame at the bridge")
                    stats = bridge.stats
                wait_until(lambda: logger.stats["bus_lost"] + logger.stats["received"] >= 2 * sent, timeout=10)
        finally:
            logger_session.close()
    vehicle.close()
    assert stats["frames_in"] == sent and stats["link_lost"] == 0 and stats["kernel_dropped"] == 0
    raw = sum(1 for topic, _, _ in read_log(path) if topic == RAW_TOPIC)
    losses = read_metadata(path)[LOSSES_METADATA]
    assert raw == sent and losses["total"] == "0" and losses["bus_lost"] == "0" and losses["link_lost"] == "0"
