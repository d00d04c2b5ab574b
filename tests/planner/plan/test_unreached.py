"""The plan says what the vehicle cannot do: modes and elements no run reaches, with the measured reason."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

import sim.uuv
from planner.plan.unreached import route_length_m, unreached, unreached_line
from sim.uuv.missionfile import load_mission

RANGE2017 = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"


def _runs(mission, n=256, seed=0):
    U = np.random.default_rng(seed).random((n, mission.dim))
    r = sim.uuv.simulate(mission, U)
    ok = r.valid
    return r.scores[ok], r.modes[ok], r.names, r.output_types


def test_a_pack_too_small_for_the_route_leaves_ts_and_ms_unreached_and_says_why():
    m = load_mission(RANGE2017)
    small = dataclasses.replace(m, vehicle=dataclasses.replace(m.vehicle, battery_wh=60.0))
    record = unreached(small, *_runs(small))
    assert "TS" in record["modes"] and "MS" in record["modes"]
    assert "mission_success" in record["elements"]
    assert "Wh" in record["reason"] and f"{route_length_m(small) / 1000:.1f} km" in record["reason"]
    line = unreached_line(record)
    assert line is not None and line.startswith("unreached: no run reaches ") and "\n" not in line


def test_a_mission_the_vehicle_can_fly_reaches_every_mode():
    m = load_mission(RANGE2017)
    record = unreached(m, *_runs(m, n=2048))
    assert record["modes"] == []
    assert "mission_success" not in record["elements"] and "safety_success" not in record["elements"]


def test_a_time_limit_shorter_than_the_route_is_the_reason():
    m = load_mission(RANGE2017)
    short = dataclasses.replace(m, time_limit_s=60.0)
    scores = np.zeros((4, 3))
    record = unreached(
        short, scores, np.array([1, 1, 0, 0]), ["mission_success", "safety_success", "x"], ("binary",) * 3
    )
    assert record["modes"] == ["MS", "TS"]
    assert "over the 1 min limit" in record["reason"]
