"""The front-seat answers a ground station as ArduSub does: both flavours against ArduSub's recorded answers.

The recording (``ardusub_answers.json``) comes from ArduSub SITL through the same sequences
(``python -m tests.sim.uuv.ardusub.conformance --record``); with ``ARDUSUB_SITL`` set the sequences
also run live against the firmware and its answers must still be the recorded ones.
"""

from __future__ import annotations

import pytest

from planner.fly.ardusub_sitl import ENV, sitl_binary
from sim.uuv.ardusub.params import FIRMWARE
from tests.sim.uuv.ardusub import conformance
from tests.support.loopback import no_new_threads

pytestmark = [pytest.mark.integration]


@pytest.fixture(scope="module")
def recorded() -> dict:
    fixture = conformance.load_fixture()
    assert fixture["firmware"] == FIRMWARE, "the parameter table and the recording come from one firmware"
    return fixture["rows"]


@pytest.mark.parametrize("flavour", conformance.FLAVOURS)
def test_every_row_matches_ardusub_or_names_its_reason(flavour, recorded):
    with no_new_threads():
        rows = conformance.compare(recorded, conformance.ours(flavour, recorded), flavour)
    print(conformance.table(rows, f"{flavour} front-seat vs {FIRMWARE}"))
    assert [r.name for r in rows if r.ours == ["(row missing)"]] == []
    for step in conformance.STEPS:  # the recording has a row for every step (an exchange's rows share its prefix)
        assert any(name.startswith(step.row) for name in recorded), step.row
    unexplained = [f"{r.name}: ArduSub {r.ardusub} / ours {r.ours}" for r in rows if not r.allowed]
    assert not unexplained, unexplained
    # an allowed difference is still a difference: the allow-list names no row that matches
    assert {r.name for r in rows if not r.matches} == set(conformance.allowed(flavour))


def test_a_changed_answer_is_caught():
    recorded = {"PARAM_SET unknown name": [], "DO_SET_MODE unknown mode 15": ["COMMAND_ACK 176 result=4"]}
    ours = {
        "PARAM_SET unknown name": ["PARAM_VALUE NO_SUCH_PARAM=1 type=9 index=-1"],
        "DO_SET_MODE unknown mode 15": [],
    }
    rows = conformance.compare(recorded, ours)
    assert [r.allowed for r in rows] == [False, False]
    assert "DIFFERS" in conformance.table(rows, "t")


def test_rates_agree_within_a_factor_of_two_on_the_same_messages():
    firmware = ["HEARTBEAT 1 Hz", "ATTITUDE 10 Hz"]
    assert conformance.rates_agree(firmware, ["HEARTBEAT 0.99 Hz", "ATTITUDE 19 Hz"])
    assert not conformance.rates_agree(firmware, ["HEARTBEAT 1 Hz", "ATTITUDE 21 Hz"])
    assert not conformance.rates_agree(firmware, ["HEARTBEAT 1 Hz", "ATTITUDE 4.9 Hz"])
    assert not conformance.rates_agree(firmware, ["HEARTBEAT 1 Hz"])  # a message not streamed
    assert not conformance.rates_agree(firmware, ["(row missing)"])
    row = conformance.Row("default streams: rates", firmware, ["HEARTBEAT 1 Hz", "ATTITUDE 3 Hz"])
    assert not row.matches and "DIFFERS" in row.verdict


@pytest.mark.sitl
@pytest.mark.slow
@pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary")
def test_the_recording_is_what_the_firmware_answers_today(recorded):
    with conformance.ardusub_sitl() as client:
        live = conformance.run(client, window=0.8, expected=recorded)
    rows = conformance.compare(recorded, live)
    print(conformance.table(rows, "live ArduSub SITL vs the recording"))
    assert [f"{r.name}: {r.ardusub} / live {r.ours}" for r in rows if not r.matches] == []
