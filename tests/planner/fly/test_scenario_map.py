"""The scenario's map reaches a logger on another process's session once, whichever of the two starts first."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bridge import keys
from bridge.logger import McapLogger
from bridge.session import open_session
from planner.fly.scenario_map import ScenarioMap, scenario_map
from sim.uuv.missionfile import load_mission
from tests.support.foxglove_check import check_channel, foxglove_channels
from tests.support.loopback import free_port, no_new_threads, wait_until

pytestmark = [pytest.mark.integration]

ROOT = Path(__file__).resolve().parents[3]
MISSION = load_mission(ROOT / "examples" / "range2017.toml")
U = np.asarray(json.loads((ROOT / "field_plans" / "range2017" / "plan.json").read_text())["scenarios"][0]["u"])


def test_the_map_holds_the_scenarios_elements_and_predicted_track():
    doc = scenario_map(MISSION, U)
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds.count("mission_area") == len(MISSION.mission_areas) and kinds.count("nogo") == len(MISSION.nogo)
    assert {"launch", "recovery", "operational_area", "predicted_track"} <= set(kinds)
    invalid = np.zeros(MISSION.dim)  # scenario row 0 of range2017: a no-go area on a mission area
    assert scenario_map(MISSION, invalid) is None


@pytest.mark.parametrize("map_first", [True, False], ids=["map-first", "logger-first"])
def test_a_logger_on_another_session_records_the_map_once(tmp_path, map_first):
    path = tmp_path / "run.mcap"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with no_new_threads():
        planner = open_session(listen=[endpoint])
        recorder = open_session(connect=[endpoint])
        try:
            wait_until(lambda: list(recorder.info.peers_zid()), what="the logger's session to connect")
            parts = [ScenarioMap(planner, "uuv1", MISSION, U), McapLogger(path, recorder, flush_interval_s=0.2)]
            if not map_first:
                parts.reverse()
            for part in parts:
                part.start()
            try:
                logger = parts[1] if map_first else parts[0]
                wait_until(lambda: logger.stats["written"] >= 2, what="the map and the logger's own token")
            finally:  # closing the logger waits for its query's answers: a second copy would be in the file
                for part in reversed(parts):
                    part.close()
        finally:
            recorder.close()
            planner.close()
    assert logger.stats["errors"] == 0 and logger.stats["written"] == logger.stats["received"]
    channels = foxglove_channels(path)
    check_channel(channels["/map/scenario"])
    [message] = channels["/map/scenario"].messages
    assert json.loads(message["geojson"]) == scenario_map(MISSION, U)
    assert keys.map_document("uuv1", "scenario") == "rapt/uuv1/map/scenario"
