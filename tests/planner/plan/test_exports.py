"""Range files of one scenario: QGroundControl .plan, QGC WPL 110 (read back by pymavlink) and GeoJSON."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"  # before pymavlink is imported (CONVENTIONS 2g)
from pymavlink import mavwp  # noqa: E402

import sim.uuv  # noqa: E402
from planner.common.geojson import geojson  # noqa: E402
from planner.plan.exports import qgc_plan, wpl, write_scenario_files  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402
from tests.support.qgc_loader import plan_errors, wpl_errors  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def _mission(name):
    return sim.uuv.load_mission(EXAMPLES / f"{name}.toml")


def _row(mission, seed=3):
    """A valid random scenario whose area priority is not the mission file's."""
    rng = np.random.default_rng(seed)
    U = rng.random((200, mission.dim))
    s = make_scenarios(mission, U)
    names = [a.name for a in mission.mission_areas]
    for i in np.flatnonzero(s.valid):
        if tuple(names[k] for k in s.order[i]) != mission.priority:
            return U[i]
    raise AssertionError("no valid scenario with a changed priority")


@pytest.fixture(scope="module", params=["range2017", "uuv18"])
def case(request):
    m = _mission(request.param)
    u = _row(m)
    return m, u, m.space.decode(u[None, :])[0], LocalFrame(m.origin_lat, m.origin_lon)


def _local(frame, lat, lon):
    return np.array(frame.to_local(lat, lon))


def _signed_area(xy):
    xy = np.asarray(xy, dtype=float)
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_plan_has_the_exact_qgc_layout(case):
    m, u, _, _ = case
    plan = qgc_plan(m, u)
    json.dumps(plan, allow_nan=False)  # JSON numbers only
    assert list(plan) == ["fileType", "geoFence", "groundStation", "mission", "rallyPoints", "version"]
    assert (plan["fileType"], plan["version"], plan["groundStation"]) == ("Plan", 1, "RAPT")
    mis = plan["mission"]
    assert set(mis) == {
        "version",
        "firmwareType",
        "vehicleType",
        "cruiseSpeed",
        "hoverSpeed",
        "globalPlanAltitudeMode",
        "plannedHomePosition",
        "items",
    }
    assert (mis["version"], mis["firmwareType"], mis["vehicleType"], mis["globalPlanAltitudeMode"]) == (2, 3, 12, 1)
    assert mis["cruiseSpeed"] == m.vehicle.cruise_speed and mis["hoverSpeed"] == 0
    assert plan["geoFence"]["version"] == 2 and plan["geoFence"]["circles"] == []
    assert plan["rallyPoints"]["version"] == 2
    items = mis["items"]
    n = len(m.waypoints) + len(m.mission_areas) + (m.transmission is not None) + 1
    assert len(items) == n
    assert [it["doJumpId"] for it in items] == list(range(1, n + 1))
    for it in items:
        assert set(it) == {
            "type",
            "autoContinue",
            "command",
            "doJumpId",
            "frame",
            "params",
            "Altitude",
            "AltitudeMode",
            "AMSLAltAboveTerrain",
        }
        assert it["type"] == "SimpleItem" and it["autoContinue"] is True and it["frame"] == 3
        assert len(it["params"]) == 7 and it["params"][6] == it["Altitude"] == -2.0
        assert it["AltitudeMode"] == 1 and it["AMSLAltAboveTerrain"] is None


def test_plan_items_follow_the_scenario(case):
    m, u, values, frame = case
    items = qgc_plan(m, u)["mission"]["items"]
    pos = [_local(frame, *it["params"][4:6]) for it in items]
    W = len(m.waypoints)
    for k, (x, y) in enumerate(m.waypoints):
        assert items[k]["command"] == 16
        np.testing.assert_allclose(pos[k], (x, y), atol=0.01)
    areas = {a.name: a for a in m.mission_areas}
    priority = values["priority"]
    assert priority != m.priority  # the fixture picked a changed order, so this can fail
    for r, name in enumerate(priority):
        it = items[W + r]
        assert it["command"] == 19 and it["params"][0] == areas[name].dwell_s
        np.testing.assert_allclose(pos[W + r], (areas[name].x, areas[name].y), atol=0.01)
    tx = items[W + len(priority)]
    assert tx["command"] == 19 and tx["params"][0] == m.transmission.duration_s
    np.testing.assert_allclose(pos[W + len(priority)], (values["tx_x"], values["tx_y"]), atol=0.01)
    assert items[-1]["command"] == 16
    np.testing.assert_allclose(pos[-1], m.recovery, atol=0.01)
    plan = qgc_plan(m, u)
    np.testing.assert_allclose(_local(frame, *plan["mission"]["plannedHomePosition"][:2]), m.launch, atol=0.01)
    np.testing.assert_allclose(_local(frame, *plan["rallyPoints"]["points"][0][:2]), m.recovery, atol=0.01)


def test_plan_fence_is_clockwise_and_at_the_scenario_positions(case):
    m, u, values, frame = case
    polys = qgc_plan(m, u)["geoFence"]["polygons"]
    assert [p["inclusion"] for p in polys] == [True] + [False] * (len(m.nogo) + len(m.barriers) + len(m.obstacles))
    local = []
    for p in polys:
        assert p["version"] == 1
        xy = np.array([_local(frame, lat, lon) for lat, lon in p["polygon"]])
        assert _signed_area(xy) < 0, "fence polygons must be clockwise"
        local.append(xy)
    op = m.operational_area
    # corners at MAVLink's degE7 (about 1 cm): the area within a centimetre's strip of its perimeter
    assert abs(-_signed_area(local[0]) - op.width * op.height) < 0.01 * 2 * (op.width + op.height)
    assert all(round(v, 7) == v for p in polys for point in p["polygon"] for v in point)
    # The first exclusion is the first no-go area, moved by the scenario (both missions vary it).
    nogo_x = values["nogo_x"]
    nogo_y = values["nogo_y"]
    np.testing.assert_allclose(local[1].mean(axis=0), (nogo_x, nogo_y), atol=0.01)
    if m.obstacles:  # the last exclusion is the last obstacle, a triangle centred on its parameters
        assert len(polys[-1]["polygon"]) == 3
        np.testing.assert_allclose(local[-1].mean(axis=0), (values["obstacle3_x"], values["obstacle3_y"]), atol=0.01)


def test_wpl_loads_in_pymavlink_and_matches_the_plan(case, tmp_path):
    m, u, _, _ = case
    text = wpl(m, u)
    lines = text.splitlines()
    assert lines[0] == "QGC WPL 110"
    for line in lines[1:]:
        assert len(line.split("\t")) == 12, line
    path = tmp_path / "s.waypoints"
    path.write_text(text)
    loader = mavwp.MAVWPLoader()
    plan = qgc_plan(m, u)
    items = plan["mission"]["items"]
    assert loader.load(str(path)) == len(items) + 1
    home = loader.wp(0)
    assert (home.seq, home.current, home.frame, home.command) == (0, 1, 0, 16)
    np.testing.assert_allclose((home.x, home.y), plan["mission"]["plannedHomePosition"][:2], atol=1e-8)
    for seq, it in enumerate(items, start=1):
        w = loader.wp(seq)
        assert (w.seq, w.current, w.frame, w.command, w.autocontinue) == (seq, 0, 3, it["command"], 1)
        np.testing.assert_allclose((w.param1, w.param2, w.param3, w.param4), it["params"][:4], atol=1e-6)
        np.testing.assert_allclose((w.x, w.y), it["params"][4:6], atol=1e-8)  # lat before lon
        assert w.z == pytest.approx(-2.0)


def test_geojson_is_lon_lat_with_closed_ccw_rings():
    m = _mission("uuv18")
    u = _row(m)
    frame = LocalFrame(m.origin_lat, m.origin_lon)
    g = geojson(m, u)
    json.dumps(g, allow_nan=False)
    assert g["type"] == "FeatureCollection"
    by_kind = {}
    for f in g["features"]:
        by_kind.setdefault(f["properties"]["kind"], []).append(f)
        assert set(f["properties"]) >= {"kind", "name"}
    launch = by_kind["launch"][0]["geometry"]
    lat, lon = frame.to_latlon(*m.launch)
    # at MAVLink's degE7, as the vehicle holds it
    assert launch["type"] == "Point" and launch["coordinates"] == [round(lon, 7), round(lat, 7)]
    assert -123 < launch["coordinates"][0] < -122 and 47 < launch["coordinates"][1] < 48  # Puget Sound, lon first
    assert len(by_kind["waypoint"]) == len(m.waypoints) and len(by_kind["recovery"]) == 1
    expected = {
        "operational_area": 1,
        "mission_area": len(m.mission_areas),
        "transmission": 1,
        "nogo": len(m.nogo),
        "barrier": len(m.barriers),
        "obstacle": len(m.obstacles),
    }
    for kind, count in expected.items():
        assert len(by_kind[kind]) == count, kind
        for f in by_kind[kind]:
            assert f["geometry"]["type"] == "Polygon"
            ring = f["geometry"]["coordinates"][0]
            assert ring[0] == ring[-1] and len(ring) >= 4
            assert _signed_area(ring[:-1]) > 0, "exterior rings must be counter-clockwise"
    assert "predicted_track" not in by_kind


def test_geojson_track_starts_at_launch_and_writes_all_files(tmp_path):
    m = _mission("range2017")
    u = _row(m)
    res = sim.uuv.simulate(m, u[None, :], trajectories=True)
    track = res.trajectories[0]
    g = geojson(m, u, track=track)
    line = [f for f in g["features"] if f["properties"]["kind"] == "predicted_track"]
    assert len(line) == 1 and line[0]["geometry"]["type"] == "LineString"
    coords = line[0]["geometry"]["coordinates"]
    assert len(coords) == track.shape[0]
    frame = LocalFrame(m.origin_lat, m.origin_lon)
    lon0, lat0 = coords[0]
    np.testing.assert_allclose(frame.to_local(lat0, lon0), m.launch, atol=0.01)
    props = line[0]["properties"]
    assert props["duration_s"] == pytest.approx(track[-1, 0] - track[0, 0])
    assert 0.0 < props["surfaced_s"] < props["duration_s"]  # this scenario surfaces to transmit
    assert props["surfaced_s"] == pytest.approx(float(np.sum(np.diff(track[:, 0])[track[:-1, 5] > 0.5])))

    paths = write_scenario_files(m, u, tmp_path / "out", "s1", track=track)
    assert {k: p.name for k, p in paths.items()} == {
        "plan": "s1.plan",
        "waypoints": "s1.waypoints",
        "geojson": "s1.geojson",
    }
    assert json.loads(paths["plan"].read_text()) == json.loads(json.dumps(qgc_plan(m, u)))
    assert paths["waypoints"].read_text() == wpl(m, u)
    assert json.loads(paths["geojson"].read_text()) == json.loads(json.dumps(g))


def test_invalid_scenario_names_u_and_writes_nothing(tmp_path):
    m = _mission("uuv18")
    u = _row(m).copy()
    rx, ry = m.recovery
    for name, v in (("obstacle1_x", rx), ("obstacle1_y", ry)):
        p = next(q for q in m.space.parameters if q.name == name)
        u[m.space.slice_of(name)] = (v - p.low) / (p.high - p.low)
    for fn in (qgc_plan, wpl, geojson):
        with pytest.raises(ValueError, match=r"^u: scenario is invalid \(an obstacle on the recovery point\)$"):
            fn(m, u)
    with pytest.raises(ValueError, match=r"^u: scenario is invalid"):
        write_scenario_files(m, u, tmp_path, "bad")
    assert list(tmp_path.iterdir()) == []
    for bad in (u[:-1], np.full(m.dim, 1.5), np.full(m.dim, np.nan)):
        with pytest.raises(ValueError, match=r"^u: ") as err:
            qgc_plan(m, bad)
        assert "\n" not in str(err.value)


FIELD_PLAN = Path(__file__).resolve().parents[3] / "field_plans" / "range2017"


@pytest.mark.parametrize("stem", sorted(p.stem for p in FIELD_PLAN.glob("*.plan")))
def test_shipped_plan_files_pass_qgroundcontrols_loader_and_mavproxys_wp_load(stem):
    """What a range crew opens: every scenario file of the bundled plan, checked by QGroundControl's
    load rules (tests/support/qgc_loader.py) and loaded as MAVProxy's ``wp load`` does (mavwp)."""
    plan_path, wpl_path = FIELD_PLAN / f"{stem}.plan", FIELD_PLAN / f"{stem}.waypoints"
    assert plan_errors(plan_path) == [] and wpl_errors(wpl_path) == []
    doc = json.loads(plan_path.read_text())
    mis = doc["mission"]
    assert (mis["version"], mis["firmwareType"], mis["vehicleType"]) == (2, 3, 12)  # ArduPilot, submarine
    assert (doc["geoFence"]["version"], doc["rallyPoints"]["version"]) == (2, 2)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(wpl_path)) == len(mis["items"]) + 1
    home = loader.wp(0)
    assert (home.seq, home.frame, home.command) == (0, 0, 16)
    np.testing.assert_allclose((home.x, home.y), mis["plannedHomePosition"][:2], atol=1e-7)
    for seq, it in enumerate(mis["items"], start=1):
        w = loader.wp(seq)
        assert (w.seq, w.frame, w.command) == (seq, it["frame"], it["command"])
        np.testing.assert_allclose((w.x, w.y, w.z), it["params"][4:7], atol=1e-7)


def test_shipped_plan_parameters_are_what_was_simulated_at_the_range_s_resolution():
    """Every scenario of the bundled plan states its parameters at their resolution (0.1 m, 1 s, 0.1 %),
    exactly as its cube point decodes: the values the range sets are the values the plan simulated."""
    plan = json.loads((FIELD_PLAN / "plan.json").read_text())
    m = _mission("range2017")
    steps = {p.name: p.resolution for p in m.space.parameters if getattr(p, "resolution", None)}
    assert steps["start_time"] == 1.0 and steps["tx_x"] == 0.1 and steps["start_battery"] == 0.001
    scenarios = plan["scenarios"] + list(plan.get("variants", []))
    assert len(scenarios) >= 10
    for sc in scenarios:
        decoded = json.loads(json.dumps(m.space.decode(np.array([sc["u"]]))[0]))
        assert sc["parameters"] == decoded, sc["id"]
        for name, step in steps.items():
            k = sc["parameters"][name] / step
            assert abs(k - round(k)) < 1e-6, (sc["id"], name, sc["parameters"][name])


def test_the_qgc_checker_refuses_what_qgroundcontrol_refuses_or_drops(tmp_path):
    m = _mission("range2017")
    good = qgc_plan(m, _row(m))
    path = tmp_path / "s.plan"

    def errors(edit) -> list[str]:
        doc = json.loads(json.dumps(good))
        edit(doc)
        path.write_text(json.dumps(doc))
        return plan_errors(path)

    assert errors(lambda d: None) == []
    assert errors(lambda d: d.pop("rallyPoints")) == ["The following required keys are missing: rallyPoints"]
    assert errors(lambda d: d.update(version=2)) == ["File version 2 is not the supported version 1"]
    assert errors(lambda d: d.update(fileType="Mission")) == ["Incorrect file type key expected:Plan actual:Mission"]
    assert errors(lambda d: d["mission"].pop("firmwareType")) == [
        "Mission: The following required keys are missing: firmwareType"
    ]
    assert errors(lambda d: d["mission"]["items"][0]["params"].pop()) == ["Mission: params key must contains 7 values"]
    assert errors(lambda d: d["mission"]["items"][1].pop("Altitude")) == [
        "Mission: The following required keys are missing: Altitude"
    ]
    assert errors(lambda d: d["mission"]["items"][0].update(autoContinue=1)) == [
        "Mission: Incorrect value type - key:type:expected autoContinue:int:Bool"
    ]
    assert errors(lambda d: d["geoFence"].update(version=1))[0].startswith("GeoFence: version 1 or none")
    assert errors(lambda d: d["geoFence"]["polygons"][0]["polygon"][0].append(0.0)) == [
        "GeoFence: Coordinate array must contain 2 values"
    ]
    assert errors(lambda d: d["rallyPoints"]["points"][0].pop()) == ["Rally: Coordinate array must contain 3 values"]
    wpl_path = tmp_path / "s.waypoints"
    wpl_path.write_text(wpl(m, _row(m)).replace("QGC WPL 110", "QGC WPL 200"))
    assert wpl_errors(wpl_path) != []
