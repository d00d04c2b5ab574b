"""Foxglove's well-known messages in the log: what is derived from the bus, and that the logger writes it."""

from __future__ import annotations

import json
import math
import socket

import pytest

from bridge import foxglove, keys
from bridge.frames import mavlink2, message_json
from bridge.logger import McapLogger, read_log
from bridge.session import open_session
from tests.support.foxglove_check import check_channel, decode, foxglove_channels, message_class
from tests.support.loopback import free_port, wait_until

NS = 1_795_790_247_083_170_978
M = mavlink2.MAVLink(None)


def _sample(msg) -> dict:
    """A MAVLink message as the bridge puts it on the bus."""
    return json.loads(message_json(msg, NS))


def _derive(fx: foxglove.FoxgloveMessages, msg) -> list[foxglove.Derived]:
    return fx.derive("mavlink", msg.get_type(), _sample(msg), NS)


def _validate(derived: list[foxglove.Derived]) -> None:
    """Each message encodes under the SDK's schema and decodes back to itself (every field the project fills)."""
    for _, name, message in derived:
        assert _same(decode(name, foxglove.schema(name).data, foxglove.encode(name, message)), message)


def _same(decoded, written) -> bool:
    """``decoded`` (from Protobuf) holds ``written``: dicts key by key, lists item by item, numbers to 1e-9
    (Protobuf keeps doubles, and a float field's single precision where the schema has one)."""
    if isinstance(written, dict):
        assert set(written) <= set(decoded), (sorted(written), sorted(decoded))
        return all(_same(decoded[k], v) for k, v in written.items())
    if isinstance(written, list):
        assert len(decoded) == len(written)
        return all(_same(d, w) for d, w in zip(decoded, written))
    if isinstance(written, float):
        assert decoded == pytest.approx(written, abs=1e-9), (decoded, written)
        return True
    assert decoded == written, (decoded, written)
    return True


def _rotate(q: dict, v: tuple[float, float, float]) -> tuple[float, float, float]:
    """Vector ``v`` rotated by the unit quaternion ``q``."""
    w, x, y, z = q["w"], q["x"], q["y"], q["z"]
    r = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return tuple(sum(r[i][j] * v[j] for j in range(3)) for i in range(3))  # type: ignore[return-value]


def test_schemas_are_the_foxglove_sdks_own():
    import foxglove as sdk

    assert set(foxglove.WELL_KNOWN) == {
        "foxglove.LocationFix",
        "foxglove.Log",
        "foxglove.FrameTransform",
        "foxglove.PosesInFrame",
        "foxglove.GeoJSON",
    }
    for name in foxglove.WELL_KNOWN:
        s = foxglove.schema(name)
        assert (s.name, s.encoding) == (name, "protobuf")
        assert s.data == getattr(sdk.messages, name.split(".")[1].replace("GeoJSON", "GeoJson")).get_schema().data
        assert message_class(name, s.data).DESCRIPTOR.full_name == name  # a descriptor set a reader can load
    with pytest.raises(ValueError, match="schema: 'foxglove.Nope'"):
        foxglove.schema("foxglove.Nope")


def test_position_fix_is_in_degrees_and_metres():
    fx = foxglove.FoxgloveMessages()
    msg = M.global_position_int_encode(1000, -338_512_345, 1_512_098_765, -12_340, -12_340, 0, 0, 0, 9000)
    derived = _derive(fx, msg)
    _validate(derived)
    [(topic, name, fix)] = derived
    assert (topic, name) == (foxglove.FIX_TOPIC, "foxglove.LocationFix")
    assert fix["latitude"] == pytest.approx(-33.8512345, abs=1e-12)
    assert fix["longitude"] == pytest.approx(151.2098765, abs=1e-12)
    assert fix["altitude"] == pytest.approx(-12.34)
    assert fix["timestamp"] == {"sec": NS // 10**9, "nsec": NS % 10**9}
    assert fix["position_covariance_type"] == 0  # unknown: MAVLink's fix carries none


@pytest.mark.parametrize(
    "severity, level",
    [(0, foxglove.FATAL), (2, foxglove.FATAL), (3, foxglove.ERROR), (4, foxglove.WARNING), (6, foxglove.INFO), (7, 1)],
)
def test_statustext_severity_maps_to_foxglove_levels(severity, level):
    derived = _derive(foxglove.FoxgloveMessages(), M.statustext_encode(severity, b"Arm: Leak Detected"))
    _validate(derived)
    [(topic, _, line)] = derived
    assert topic == foxglove.LOG_TOPIC
    assert (line["level"], line["message"], line["name"]) == (level, "Arm: Leak Detected", "vehicle")


def test_local_pose_is_enu_with_attitudes_yaw_and_the_trail_stays_bounded():
    fx = foxglove.FoxgloveMessages()
    assert _derive(fx, M.attitude_encode(0, 0.0, 0.0, math.radians(90.0), 0, 0, 0)) == []  # heading east
    derived = _derive(fx, M.local_position_ned_encode(0, 10.0, 20.0, 5.0, 0, 0, 0))
    _validate(derived)
    (tf_topic, _, tf), (trail_topic, _, trail) = derived
    assert (tf_topic, trail_topic) == (foxglove.TF_TOPIC, foxglove.TRAIL_TOPIC)
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == (foxglove.LOCAL_FRAME, foxglove.VEHICLE_FRAME)
    # 10 m north, 20 m east, 5 m down -> ENU (20, 10, -5); the vehicle's nose (its x axis) points east
    assert tf["translation"] == {"x": 20.0, "y": 10.0, "z": -5.0}
    assert _rotate(tf["rotation"], (1.0, 0.0, 0.0)) == pytest.approx((1.0, 0.0, 0.0), abs=1e-4)
    assert trail["frame_id"] == foxglove.LOCAL_FRAME and len(trail["poses"]) == 1
    trails = [trail]
    for k in range(1, 2000):  # a 2000 s run at 1 Hz
        derived = _derive(fx, M.local_position_ned_encode(k * 1000, float(k), 0.0, 5.0, 0, 0, 0))
        trails += [m for t, _, m in derived if t == foxglove.TRAIL_TOPIC]
    assert max(len(t["poses"]) for t in trails) <= foxglove.MAX_TRAIL
    assert len(trails) < 500  # not one per pose: the trail is re-sent only when it grows
    poses = trails[-1]["poses"]
    assert poses[0]["position"]["y"] == 10.0 and poses[-1]["position"]["y"] > 1900  # the whole run, thinned
    _validate([(foxglove.TRAIL_TOPIC, "foxglove.PosesInFrame", trails[-1])])


def test_autonomy_events_are_logged_on_change_with_their_level():
    fx = foxglove.FoxgloveMessages()

    def lines(source, obj):
        derived = fx.derive("status", source, obj, NS)
        _validate(derived)
        return [(m["level"], m["name"], m["message"]) for _, _, m in derived]

    status = {"tick_ms": 0, "goal": 0, "returning": False, "return_reason": 0, "wp_aborted": [False, False]}
    assert lines("autonomy", status) == [(foxglove.INFO, "autonomy", "goal: waypoint")]
    assert lines("autonomy", {**status, "tick_ms": 2000}) == []  # every decision, but no event
    aborted = {**status, "wp_aborted": [False, True]}
    assert lines("autonomy", aborted) == [(foxglove.WARNING, "autonomy", "goal: waypoint; waypoints aborted: [1]")]
    home = {**aborted, "goal": 3, "returning": True, "return_reason": 2}
    assert lines("autonomy", home)[0][2] == "goal: return (returning: battery); waypoints aborted: [1]"
    step = {"name": "guided", "status": "failed", "wall_s": 1.0, "time_boot_ms": 5, "detail": "DENIED"}
    assert lines("bringup", step) == [(foxglove.ERROR, "bringup", "bring-up guided failed: DENIED")]
    took = {"event": "intervention", "reason": "nogo", "detail": "in N1", "time_boot_ms": 9, "action": "surface"}
    assert lines("watchdog", took)[0][:2] == (foxglove.ERROR, "watchdog")
    assert lines("referee", {"ended": "recovered", "time_boot_ms": 9, "t": 3.0}) == [
        (foxglove.INFO, "referee", "run ended: recovered")
    ]
    assert lines("odd", {"state": "transit"}) == []  # free JSON of other processes is not an event


def test_goal_and_return_names_follow_the_autonomy():
    from sim.uuv import autonomy

    assert foxglove.GOALS == {
        autonomy.GOAL_WAYPOINT: "waypoint",
        autonomy.GOAL_TRANSMIT: "transmit",
        autonomy.GOAL_SURVEY: "survey",
        autonomy.GOAL_RETURN: "return",
    }
    assert set(foxglove.RETURN_REASONS) == {
        autonomy.RETURN_NONE,
        autonomy.RETURN_COMPLETE,
        autonomy.RETURN_FUEL,
        autonomy.RETURN_TIME,
    }


def test_logger_writes_foxglove_channels_beside_its_own(tmp_path):
    """On a real (loopback) bus: a map document, a fix and a STATUSTEXT become Foxglove channels; the
    MAVLink JSON channels stay as they were and the map is written once, as its GeoJSON channel only."""
    path = tmp_path / "run.mcap"
    document = {
        "type": "FeatureCollection",
        "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [151.2, -33.8]}}],
    }
    fix = M.global_position_int_encode(1000, -338_512_345, 1_512_098_765, -2000, -2000, 0, 0, 0, 0)
    text = M.statustext_encode(4, b"EKF variance")
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
    try:
        with McapLogger(path, session, vehicle="uuv1", flush_interval_s=0.2) as logger:
            session.put(keys.map_document("uuv1", "scenario"), json.dumps(document))
            session.put(keys.telemetry("uuv1", "GLOBAL_POSITION_INT"), message_json(fix, NS))
            session.put(keys.telemetry("uuv1", "STATUSTEXT"), message_json(text, NS))
            wait_until(lambda: logger.stats["derived"] >= 2, what="the derived messages")
        stats = logger.stats
    finally:
        session.close()
    assert stats["errors"] == 0 and stats["written"] == stats["received"] and stats["derived"] == 2
    channels = foxglove_channels(path)
    assert {t: c.schema_name for t, c in channels.items()} == {
        "/map/scenario": "foxglove.GeoJSON",
        foxglove.FIX_TOPIC: "foxglove.LocationFix",
        foxglove.LOG_TOPIC: "foxglove.Log",
    }
    for channel in channels.values():
        check_channel(channel)
    [doc] = channels["/map/scenario"].messages
    assert json.loads(doc["geojson"]) == document
    assert channels[foxglove.FIX_TOPIC].messages[0]["latitude"] == pytest.approx(-33.8512345)
    assert channels[foxglove.LOG_TOPIC].messages[0]["message"] == "EKF variance"
    topics = [t for t, _, _ in read_log(path)]
    assert keys.telemetry("uuv1", "GLOBAL_POSITION_INT") in topics  # today's channel, unchanged
    assert keys.map_document("uuv1", "scenario") not in topics  # the document once, as GeoJSON
