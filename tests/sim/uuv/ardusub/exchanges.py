"""Conformance exchanges of many messages: the default streams, the mission protocol, a GUIDED velocity target.

Each fills rows of its own (their names share the step's row as prefix), reduced as
:func:`tests.sim.uuv.ardusub.ground_station.canonical` reduces single answers.
"""

from __future__ import annotations

import math
import os
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from tests.sim.uuv.ardusub.ground_station import SPONTANEOUS, Client, canonical, is_answer  # noqa: E402

mav = mavutil.mavlink

#: Vehicle seconds over which the default streams are counted.
STREAM_WINDOW_S = 10.0
#: Streamed messages a back-seat reads; their default rates must agree within a factor of 2.
RELIED_ON = (
    "HEARTBEAT",
    "SYS_STATUS",
    "GPS_RAW_INT",
    "GLOBAL_POSITION_INT",
    "LOCAL_POSITION_NED",
    "ATTITUDE",
    "VFR_HUD",
    "SYSTEM_TIME",
    "BATTERY_STATUS",
    "EKF_STATUS_REPORT",
    "MISSION_CURRENT",
)


def default_streams(client: Client, window: float) -> dict[str, list[str]]:
    """What the vehicle streams unasked: every message type, and the rates (per vehicle second) of those relied on.

    Rates are counted against the vehicle's clock (ATTITUDE's ``time_boot_ms``), so a speed-up
    does not change them; a clock that stands still for a wall second (lock-step) ends the count.
    """
    counts: dict[str, int] = {}
    first = last = None
    ticked = time.monotonic()
    while time.monotonic() - ticked < 1.0 and (first is None or last - first < STREAM_WINDOW_S * 1000):
        msg = client.conn.recv_match(blocking=True, timeout=0.05)
        if msg is None or msg.get_type() == "BAD_DATA":
            continue
        if msg.get_type() == "ATTITUDE":  # the vehicle's clock, 10 Hz
            if last is None or msg.time_boot_ms > last:
                ticked = time.monotonic()
            first = msg.time_boot_ms if first is None else first
            last = msg.time_boot_ms
        if first is not None and not is_answer(msg):
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    span = 0.0 if first is None or last is None else (last - first) / 1000
    rates = [f"{name} {counts[name] / span:.2g} Hz" for name in RELIED_ON if name in counts and span > 0]
    return {"default streams: message types": sorted(counts), "default streams: rates": rates}


#: The mission uploaded: a placeholder for home (item 0, 0.001 deg north of home) and two
#: waypoints 5 m deep north-east of home (frame, degrees of latitude and longitude from home, z).
MISSION_ITEMS = (
    (mav.MAV_FRAME_GLOBAL, 0.001, 0.0, 0.0),
    (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0.0002, 0.0001, -5.0),
    (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0.0004, 0.0003, -5.0),
)


def mission_protocol(client: Client, window: float) -> dict[str, list[str]]:
    """Upload a three-item mission (MISSION_COUNT, the vehicle asks for each item), then read it back."""
    client.drain()
    client.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
    home = client.wait_for("HOME_POSITION")
    lat0, lon0 = home.latitude / 1e7, home.longitude / 1e7
    sent = [(frame, int(round((lat0 + dlat) * 1e7)), int(round((lon0 + dlon) * 1e7)), z)
            for frame, dlat, dlon, z in MISSION_ITEMS]  # fmt: skip
    client.drain()
    client.conn.mav.mission_count_send(1, 1, len(sent), mav.MAV_MISSION_TYPE_MISSION)
    upload: list[str] = []
    deadline, done = time.monotonic() + max(window, 1.0) * 10, None
    while time.monotonic() < (deadline if done is None else min(deadline, done + client.grace_s)):
        msg = client.conn.recv_match(
            type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK", "STATUSTEXT"], blocking=True, timeout=0.02
        )
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "STATUSTEXT":
            if not SPONTANEOUS.match(msg.text):
                upload.append(canonical(msg))
            continue
        if kind == "MISSION_ACK":
            upload.append(f"MISSION_ACK type={msg.type} mission_type={msg.mission_type}")
            done = time.monotonic()
            continue
        entry = f"{kind} seq={msg.seq} mission_type={msg.mission_type}"
        if not upload or upload[-1] != entry:  # a re-ask of the same item is not an answer of its own
            upload.append(entry)
        if 0 <= msg.seq < len(sent):
            frame, lat, lon, z = sent[msg.seq]
            client.conn.mav.mission_item_int_send(
                1, 1, msg.seq, frame, mav.MAV_CMD_NAV_WAYPOINT, int(msg.seq == 0), 1, 0, 2.0, 0, 0, lat, lon, z,
                mav.MAV_MISSION_TYPE_MISSION,
            )  # fmt: skip
    client.drain()
    client.conn.mav.mission_request_list_send(1, 1, mav.MAV_MISSION_TYPE_MISSION)
    count = client.wait_for("MISSION_COUNT")
    download = [f"MISSION_COUNT count={count.count} mission_type={count.mission_type}"]
    for seq in range(count.count):
        client.conn.mav.mission_request_int_send(1, 1, seq, mav.MAV_MISSION_TYPE_MISSION)
        item = client.wait_for("MISSION_ITEM_INT", ok=lambda m, seq=seq: m.seq == seq)
        download.append(_mission_item(item, sent, (home.latitude, home.longitude)))
    client.conn.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, mav.MAV_MISSION_TYPE_MISSION)
    return {"mission upload": upload, "mission download": download}


def _mission_item(item, sent: list, home: tuple[int, int]) -> str:
    """A MISSION_ITEM_INT read back: its fields, and where it is (as uploaded, home, elsewhere)."""
    at = "elsewhere"
    if item.seq < len(sent) and (item.x, item.y) == tuple(sent[item.seq][1:3]):
        at = "as uploaded"
    elif abs(item.x - home[0]) <= 1 and abs(item.y - home[1]) <= 1:
        at = "at HOME_POSITION"
    z = "" if item.seq == 0 else f" z={item.z:g}"  # home's altitude is where the vehicle booted
    return (
        f"MISSION_ITEM_INT seq={item.seq} frame={item.frame} command={item.command} current={item.current} "
        f"autocontinue={item.autocontinue} params={item.param1:g},{item.param2:g},{item.param3:g},{item.param4:g}"
        f"{z} {at}"
    )


#: The GUIDED velocity target: 1 m/s north, velocity only (position, acceleration, yaw and yaw rate ignored).
VELOCITY_ONLY_MASK = 0b110111000111
TARGET_MS = 1.0
#: Vehicle seconds the target is sent for (every REFRESH_S), then watched after the last one.
FLY_S, REFRESH_S, WATCH_S = 8.0, 0.5, 8.0
#: ArduSub zeroes a velocity target this many vehicle seconds after the last one (GUIDED_POSVEL_TIMEOUT_MS).
TIMEOUT_S = 3.0


def guided_velocity(client: Client, window: float) -> dict[str, list[str]]:
    """Fly a velocity target in GUIDED (armed), stop sending it and watch the vehicle after the timeout."""
    answers: list[str] = []
    targets: set[str] = set()
    speeds: list[tuple[float, float, float]] = []  # (vehicle s since the first target, north m/s, east m/s)
    now = start = last_sent = None
    ticked = time.monotonic()
    while time.monotonic() - ticked < 1.0:  # a vehicle whose clock stands still (lock-step) is left after 1 s
        if now is not None and start is not None and now - start > FLY_S + WATCH_S:
            break
        if (
            now is not None
            and (start is None or now - start < FLY_S)
            and (last_sent is None or now - last_sent >= REFRESH_S)
        ):
            client.conn.mav.set_position_target_local_ned_send(
                int(now * 1000), 1, 1, mav.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_MASK, 0, 0, 0, TARGET_MS, 0, 0, 0, 0, 0, 0, 0
            )  # fmt: skip
            start = now if start is None else start
            last_sent = now
        msg = client.conn.recv_match(blocking=True, timeout=0.02)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "GLOBAL_POSITION_INT":
            if now is None or msg.time_boot_ms / 1000 > now:
                ticked = time.monotonic()
            now = msg.time_boot_ms / 1000
            if start is not None:
                speeds.append((now - start, msg.vx / 100, msg.vy / 100))
        elif kind in ("POSITION_TARGET_LOCAL_NED", "POSITION_TARGET_GLOBAL_INT"):
            targets.add(f"{kind} frame={msg.coordinate_frame} type_mask={msg.type_mask}")
        elif is_answer(msg):
            answers.append(canonical(msg))
    rows = {
        "GUIDED velocity target: answers": answers,
        "GUIDED velocity target: POSITION_TARGET streamed": sorted(targets),
    }
    return rows | _timeout_rows(speeds, 0.0 if start is None or last_sent is None else last_sent - start)


def _timeout_rows(speeds: list[tuple[float, float, float]], stop: float) -> dict[str, list[str]]:
    """What the vehicle did with the target (``speeds`` as sampled, the last target sent ``stop`` s in)."""
    reached = max((vn for t, vn, _ in speeds if t <= stop), default=0.0)
    after = [(t - stop, math.hypot(vn, ve)) for t, vn, ve in speeds if t > stop]
    held = max((v for t, v in after if t <= 0.5), default=0.0)  # the speed when the last target went out
    slowing = next((t for t, v in after if v < 0.9 * held), None) if held > 0 else None
    braked = slowing is not None and any(v < 0.5 * held for t, v in after if t <= slowing + 1.0)
    early, late = TIMEOUT_S - 0.5, TIMEOUT_S + 1.5  # the last target's delivery and a 3 Hz report's spacing
    return {
        "GUIDED velocity target: speed": [f"north speed reached >= {TARGET_MS / 2:g} m/s: {reached >= TARGET_MS / 2}"],
        "GUIDED velocity target: timeout": [
            f"starts slowing {early:g}-{late:g} s after the last target: {slowing is not None and early <= slowing <= late}"
        ],
        "GUIDED velocity target: braking": [
            f"below half the speed within 1 s of slowing: {braked}",
            f"below 0.1 m/s {WATCH_S:g} s after the last target: {bool(after) and after[-1][1] < 0.1}",
        ],
    }
