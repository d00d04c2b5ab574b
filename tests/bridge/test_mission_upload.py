"""The mission upload state machine without sockets: every rule of bridge.mission_upload on a fake clock."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.frames import mavlink2
from bridge.mission_upload import COUNT, MissionItem, MissionUpload, describe, mission_items
from rapt.errors import InputError, LinkTimeoutError

M = mavlink2
ACCEPTED, INVALID_SEQUENCE, NO_SPACE = M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_INVALID_SEQUENCE, M.MAV_MISSION_NO_SPACE


def waypoints(n: int) -> list[MissionItem]:
    return [MissionItem.waypoint(i, 47.6953287 + 1e-4 * i, -122.6264071, -2.0 * i) for i in range(n)]


def test_a_clean_upload_answers_each_request_and_ends_on_the_ack():
    up = MissionUpload(3, timeout_s=1.5)
    assert up.start(10.0) == [COUNT] and up.deadline == 11.5
    assert up.step == "MISSION_COUNT: no MISSION_REQUEST for item 0"
    assert up.on_request(0, 0, 10.1) == [0] and up.deadline == pytest.approx(11.6)
    assert up.on_request(1, 0, 10.2) == [1]
    assert up.step == "item 1: no MISSION_REQUEST for item 2"
    assert up.on_request(2, 0, 10.3) == [2] and up.step == "item 2: no MISSION_ACK"
    assert not up.done
    assert up.on_ack(ACCEPTED, 0, 10.4) == []
    assert up.done and up.result == ACCEPTED and up.deadline == math.inf
    assert up.on_request(0, 0, 10.5) == [] and up.resent == 0 and up.nacks == []


def test_an_empty_upload_clears_the_mission_with_count_zero():
    up = MissionUpload(0)
    assert up.start(0.0) == [COUNT] and up.step == "MISSION_COUNT 0: no MISSION_ACK"
    up.on_ack(ACCEPTED, 0, 0.1)
    assert up.done and up.result == ACCEPTED


def test_a_timeout_sends_the_last_message_again_then_names_the_step():
    up = MissionUpload(3, timeout_s=0.5, retries=2)
    up.start(0.0)
    assert up.on_timeout(0.5) == [COUNT] and up.deadline == 1.0
    assert up.on_request(0, 0, 0.7) == [0]  # progress: the tries start again
    assert up.on_timeout(1.2) == [0]
    assert up.on_timeout(1.7) == [0]
    with pytest.raises(LinkTimeoutError) as info:
        up.on_timeout(2.2)
    assert str(info.value) == "upload_mission: item 0: no MISSION_REQUEST for item 1 after 3 tries, 0.5 s each"
    assert up.resent == 3 and not up.done


def test_a_vehicle_that_never_answers_times_out_at_mission_count():
    up = MissionUpload(2, timeout_s=1.5, retries=0, what="upload")
    up.start(0.0)
    with pytest.raises(LinkTimeoutError, match=r"^upload: MISSION_COUNT: no MISSION_REQUEST for item 0 after 1 tries"):
        up.on_timeout(1.5)


def test_no_final_ack_is_named_as_such():
    up = MissionUpload(1, timeout_s=1.0, retries=1)
    up.start(0.0)
    up.on_request(0, 0, 0.1)
    assert up.on_timeout(1.1) == [0]
    with pytest.raises(LinkTimeoutError, match="item 0: no MISSION_ACK after 2 tries"):
        up.on_timeout(2.1)


def test_a_request_asked_again_is_answered_again_without_counting_as_progress():
    up = MissionUpload(3, timeout_s=1.0)
    up.start(0.0)
    up.on_request(0, 0, 0.2)
    up.on_request(1, 0, 0.4)
    deadline = up.deadline
    assert up.on_request(1, 0, 0.9) == [1]  # ArduPilot asks again after 1 s of vehicle time
    assert up.on_request(0, 0, 0.95) == [0]  # an older one too: answer what is asked
    assert up.deadline == deadline and up.resent == 2
    assert up.on_request(2, 0, 1.0) == [2] and up.deadline == 2.0


def test_a_nack_followed_by_a_request_does_not_end_the_upload():
    """ArduPilot NACKs an item out of sequence (MAV_MISSION_INVALID_SEQUENCE) and asks again."""
    up = MissionUpload(2, timeout_s=1.0)
    up.start(0.0)
    up.on_request(0, 0, 0.1)
    up.on_ack(INVALID_SEQUENCE, 0, 0.2)
    assert not up.done and up.nacks == [INVALID_SEQUENCE]
    assert up.on_request(0, 0, 0.3) == [0]  # asked again: the same item
    up.on_request(1, 0, 0.4)  # progress: the NACK is forgotten
    assert up.on_timeout(1.4) == [1]  # a timeout now sends again, it does not end with the NACK
    up.on_ack(ACCEPTED, 0, 1.5)
    assert up.done and up.result == ACCEPTED and up.nacks == [INVALID_SEQUENCE]


def test_a_nack_without_progress_after_it_ends_the_upload_with_that_result():
    up = MissionUpload(300, timeout_s=1.0)
    up.start(0.0)
    up.on_ack(NO_SPACE, 0, 0.9)
    assert not up.done and up.deadline == pytest.approx(1.9)  # a whole timeout to ask again
    assert up.on_timeout(1.9) == []  # no exception: the vehicle did answer
    assert up.done and up.result == NO_SPACE and describe(up.result) == "MAV_MISSION_NO_SPACE"


def test_nacks_never_stretch_the_wait_past_what_the_retries_allow():
    up = MissionUpload(2, timeout_s=1.0, retries=1)
    up.start(0.0)
    up.on_request(0, 0, 0.0)  # progress at 0: give up by 2.0 whatever comes
    assert up.on_timeout(1.0) == [0]
    up.on_ack(M.MAV_MISSION_ERROR, 0, 1.8)
    assert up.deadline == 2.0
    up.on_timeout(2.0)
    assert up.result == M.MAV_MISSION_ERROR


def test_an_invalid_sequence_nack_ends_nothing_the_timeout_sends_again():
    """An item that crossed the vehicle's repeated request arrives twice: ArduPilot NACKs the copy and waits."""
    up = MissionUpload(2, timeout_s=1.0)
    up.start(0.0)
    up.on_request(0, 0, 0.1)
    up.on_ack(INVALID_SEQUENCE, 0, 0.2)
    assert up.deadline == pytest.approx(1.1)
    assert up.on_timeout(1.1) == [0] and not up.done and up.nacks == [INVALID_SEQUENCE]


def test_an_early_accept_and_other_mission_types_are_not_ours():
    up = MissionUpload(2, mission_type=M.MAV_MISSION_TYPE_FENCE)
    up.start(0.0)
    up.on_ack(ACCEPTED, M.MAV_MISSION_TYPE_FENCE, 0.1)  # before any item: another upload's
    assert not up.done
    assert up.on_request(0, M.MAV_MISSION_TYPE_MISSION, 0.2) == []  # the mission's, not the fence's
    assert up.on_request(5, M.MAV_MISSION_TYPE_FENCE, 0.2) == []  # out of range
    assert up.on_request(0, M.MAV_MISSION_TYPE_FENCE, 0.3) == [0]
    up.on_request(1, M.MAV_MISSION_TYPE_FENCE, 0.4)
    up.on_ack(ACCEPTED, M.MAV_MISSION_TYPE_MISSION, 0.5)
    assert not up.done
    up.on_ack(ACCEPTED, M.MAV_MISSION_TYPE_FENCE, 0.6)
    assert up.done and up.result == ACCEPTED


def test_bad_arguments_are_named():
    for kwargs, name in [
        ({"mission_type": 3}, "mission_type"),
        ({"timeout_s": 0}, "timeout"),
        ({"retries": -1}, "retries"),
        ({"retries": True}, "retries"),
    ]:
        with pytest.raises(InputError, match=f"^{name}: "):
            MissionUpload(1, **kwargs)
    with pytest.raises(InputError, match="^count: "):
        MissionUpload(-1)


def test_items_are_checked_and_named_by_index_and_field():
    items = waypoints(3)
    assert mission_items(items) == items
    for bad, pattern in [
        ([items[1]], r"^items\[0\]\.seq: expected 0"),
        ([items[0], "wp"], r"^items\[1\]: expected a MissionItem"),
        ([MissionItem(0, 3, 16, x=1.5)], r"^items\[0\]\.x: expected an int"),
        ([MissionItem(0, 3, 16, x=2**31)], r"^items\[0\]\.x: expected an int"),
        ([MissionItem(0, 3, 16, current=True)], r"^items\[0\]\.current: expected an int"),
        ([MissionItem(0, 3, 16, z=math.nan)], r"^items\[0\]\.z: expected a finite"),
        ([MissionItem(0, 3, 16, param4="yaw")], r"^items\[0\]\.param4: expected a number"),
    ]:
        with pytest.raises(InputError, match=pattern) as info:
            mission_items(bad)
        assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="^items: expected a sequence"):
        mission_items("items")
    # NaN params are MAVLink's "no change": allowed
    assert mission_items([MissionItem(0, 3, 16, param4=math.nan)])[0].param4 != 0


def test_items_round_trip_through_mission_item_int_messages():
    wp = MissionItem.waypoint(1, 47.6955, -122.6264, -2.5, hold_s=3.0)
    assert (wp.x, wp.y, wp.z, wp.param1) == (476955000, -1226264000, -2.5, 3.0)
    assert (wp.frame, wp.command, wp.current, wp.autocontinue) == (M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 16, 0, 1)
    msg = wp.to_message(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert (msg.target_system, msg.target_component, msg.mission_type) == (1, 1, 0)
    decoded = M.MAVLink(None, 1, 191).decode(bytearray(msg.pack(M.MAVLink(None, 1, 191))))
    assert MissionItem.from_message(decoded) == wp
    assert mission_items([waypoints(1)[0], msg]) == [waypoints(1)[0], wp]


class ArduPilotLike:
    """The vehicle side as ArduPilot's MissionItemProtocol runs it: asks for item i, NACKs an item out of
    sequence, asks again after ``resend_s`` and gives up (OPERATION_CANCELLED) after ``cancel_s``."""

    def __init__(self, resend_s=1.0, cancel_s=8.0):
        self.resend_s, self.cancel_s = resend_s, cancel_s
        self.receiving, self.count, self.i = False, 0, 0
        self.items: list[int] = []
        self.last_request = self.last_receive = 0.0

    def on_count(self, count, now):
        self.receiving, self.count, self.i, self.items = count > 0, count, 0, []
        self.last_request = self.last_receive = now
        return [("ack", ACCEPTED)] if count == 0 else [("request", 0)]

    def on_item(self, seq, now):
        if not self.receiving:
            return []
        if seq != self.i:
            return [("ack", INVALID_SEQUENCE)]
        self.items.append(seq)
        self.i += 1
        self.last_receive = self.last_request = now
        if self.i == self.count:
            self.receiving = False
            return [("ack", ACCEPTED)]
        return [("request", self.i)]

    def tick(self, now):
        if not self.receiving:
            return []
        if now - self.last_receive > self.cancel_s:
            self.receiving = False
            return [("ack", M.MAV_MISSION_OPERATION_CANCELLED)]
        if now - self.last_request > self.resend_s:
            self.last_request = now
            return [("request", self.i)]
        return []


@settings(max_examples=200, deadline=None, database=None)
@given(
    count=st.integers(0, 6),
    drops=st.lists(st.booleans(), max_size=80),
    delay=st.sampled_from([0.01, 0.3, 1.2]),
)
def test_over_a_lossy_link_the_upload_is_accepted_complete_or_times_out_naming_a_step(count, drops, delay):
    """Random message loss both ways, replies delayed: either every item arrived in order and the
    result is ACCEPTED, or a LinkTimeoutError or a NACK result ends it; never a hang."""
    vehicle, up = ArduPilotLike(), MissionUpload(count, timeout_s=1.5, retries=5)
    lost = iter(drops)
    in_flight: list[tuple[float, str, tuple]] = []  # (arrival, to, message)
    now = 0.0

    def send(to, messages):
        for message in messages:
            if not next(lost, False):
                in_flight.append((now + delay, to, message))

    send("vehicle", [("count", count)] if up.start(now) == [COUNT] else [])
    try:
        while not up.done:
            assert now < 600, "the upload must end"
            now = round(now + 0.05, 2)
            for arrival, to, message in sorted(m for m in in_flight if m[0] <= now):
                in_flight.remove((arrival, to, message))
                kind, value = message
                if to == "vehicle":
                    send("ground", vehicle.on_count(value, now) if kind == "count" else vehicle.on_item(value, now))
                elif kind == "request":
                    send("vehicle", [("item", s) for s in up.on_request(value, 0, now)])
                else:
                    up.on_ack(value, 0, now)
            send("ground", vehicle.tick(now))
            if not up.done and now >= up.deadline:
                sent = up.on_timeout(now)
                send("vehicle", [("count", count) if s == COUNT else ("item", s) for s in sent])
    except LinkTimeoutError as error:
        assert any(drops), "a link that loses nothing never times out"
        assert str(error).startswith("upload_mission: ") and "\n" not in str(error)
        return
    if up.result == ACCEPTED:
        assert vehicle.items == list(range(count)) and not vehicle.receiving
    else:  # only the vehicle giving up ends an upload with a NACK here
        assert up.result == M.MAV_MISSION_OPERATION_CANCELLED and up.result in up.nacks
