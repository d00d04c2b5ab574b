"""ArduSub's real firmware in the loop: the SITL launcher, and the bridge bringing the vehicle up as an operator would.

These tests need the ArduSub SITL binary named by ``ARDUSUB_SITL`` (CI sets it from
``../shared/ardusub/ardusub``) and skip with that reason where it is absent. The
bridge talks to the firmware over loopback TCP MAVLink and publishes on a real Zenoh
session; every process and thread is gone when a test ends.
"""

from __future__ import annotations

import json
import time

import pytest

from bridge import keys
from bridge.mavlink_bridge import MavlinkBridge
from bridge.session import open_session
from planner.ardusub_sitl import ENV, ArduSubSitl, sitl_binary
from rapt.errors import InputError, MissingFileError
from tests.loopback import free_port, wait_until

#: range2017's launch point (lat, lon, alt, heading), where a range team would put the vehicle.
LAUNCH = (47.6953287, -122.6264071, 0.0, 0.0)
MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED = 0, 4
GUIDED = 4
SAFETY_ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")


def test_the_launcher_names_what_is_missing_in_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    with pytest.raises(InputError, match=f"binary: set {ENV}"):
        ArduSubSitl(LAUNCH)
    with pytest.raises(MissingFileError, match="does not exist") as info:
        ArduSubSitl(LAUNCH, binary=tmp_path / "ardusub")
    assert "\n" not in str(info.value)


@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_the_bridge_gets_guided_only_once_the_estimator_is_ready_then_arms_and_disarms():
    """A cold boot at the launch point: GUIDED is retried until ArduSub accepts it, then armed in GUIDED."""
    with ArduSubSitl(LAUNCH, speedup=10) as sitl:
        session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
        heartbeats: list[dict] = []
        sub = session.declare_subscriber(
            keys.telemetry("uuv1", "HEARTBEAT"), lambda s: heartbeats.append(json.loads(s.payload.to_bytes()))
        )
        try:
            with MavlinkBridge(sitl.connection, session, vehicle="uuv1", allow_commands=True) as bridge:
                wait_until(lambda: bridge.target is not None, timeout=30, what="ArduSub's first HEARTBEAT")
                first = wait_until(lambda: heartbeats and heartbeats[0], timeout=10, what="HEARTBEAT on the bus")
                assert (first["type"], first["autopilot"]) == (12, 3)  # MAV_TYPE_SUBMARINE, ARDUPILOTMEGA
                assert not first["base_mode"] & SAFETY_ARMED

                answers = []
                deadline = time.monotonic() + 120  # the EKF needs about 40 s of vehicle time
                while time.monotonic() < deadline:
                    answers.append(bridge.set_mode("GUIDED"))
                    if answers[-1] == MAV_RESULT_ACCEPTED:
                        break
                    time.sleep(0.5)
                assert answers[-1] == MAV_RESULT_ACCEPTED, answers
                assert set(answers[:-1]) <= {MAV_RESULT_FAILED}  # "GUIDED requires position" until then

                assert bridge.arm(True) == MAV_RESULT_ACCEPTED
                wait_until(
                    lambda: heartbeats[-1]["custom_mode"] == GUIDED and heartbeats[-1]["base_mode"] & SAFETY_ARMED,
                    timeout=10,
                    what="an armed GUIDED heartbeat",
                )
                assert bridge.arm(False) == MAV_RESULT_ACCEPTED
                wait_until(lambda: not heartbeats[-1]["base_mode"] & SAFETY_ARMED, timeout=10, what="disarmed")
        finally:
            sub.undeclare()
            session.close()
        process = sitl.process
    assert process is not None and process.poll() is not None  # stopped by its id at exit
