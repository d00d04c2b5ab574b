"""Mission files (sim.uuv.missionfile), the shipped examples, and the local frame (sim.uuv.geo)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rapt.errors import FileFormatError
from rapt.scoretree import ScoreTree
from rapt.space import Continuous, Permutation
from sim.uuv.geo import LocalFrame, from_degE7, to_degE7
from sim.uuv.metrics import metric_names
from sim.uuv.mission import Binding, Mission
from sim.uuv.missionfields import MissionFileError
from sim.uuv.missionfile import load_mission

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def load(name: str) -> Mission:
    return load_mission(EXAMPLES / f"{name}.toml")


def tree(m: Mission) -> ScoreTree:
    return ScoreTree.from_mapping(m.score_tree)


def leaf_columns(m: Mission) -> int:
    return sum(len(n.indices) for n in tree(m).leaves())


# --------------------------------------------------------------------------- examples
@pytest.mark.parametrize("name, n_params, dim", [("uuv18", 18, 20), ("range2017", 13, 15), ("imitation7", 7, 7)])
def test_examples_load_with_their_parameter_counts(name, n_params, dim):
    m = load(name)
    assert m.name == name
    assert len(m.space.parameters) == n_params
    assert m.dim == dim
    assert len(m.bindings) == n_params
    assert [b.parameter for b in m.bindings] == m.space.names
    assert m.source.endswith(f"{name}.toml")


@pytest.mark.parametrize("name", ["uuv18", "range2017", "imitation7"])
def test_example_score_trees_cover_every_column_once(name):
    m = load(name)
    t = tree(m)
    n = len(metric_names(m))
    t.validate(n)
    cols = [i for node in t.nodes() for i in node.indices]
    assert sorted(cols) == list(range(n))
    assert t.depth == 4
    assert t.indices == (0, 1)  # mission and safety success at the root
    assert all(node.name for node in t.nodes())


def test_uuv18_layout_and_tree():
    m = load("uuv18")
    assert m.operational_area.width == m.operational_area.height == 3000
    assert len(m.waypoints) == 3 and [a.name for a in m.mission_areas] == ["A", "B", "C"]
    assert (m.transmission.width, m.transmission.height) == (700, 750)
    assert [(z.width, z.height) for z in m.nogo] == [(400, 500)]
    assert len(m.barriers) == 3 and len(m.obstacles) == 3 and m.recovery_radius == 15
    assert leaf_columns(m) >= 60
    level2 = [c.name for c in tree(m).children]
    assert level2 == [
        "waypoints",
        "mission areas",
        "transmission",
        "mission time",
        "collisions",
        "no-go areas",
        "operational area",
        "recovery",
        "surfacing",
    ]
    collisions = tree(m).children[4]
    assert [c.name for c in collisions.children] == [
        "obstacle O1",
        "obstacle O2",
        "obstacle O3",
        "barrier B1",
        "barrier B2",
        "barrier S",
    ]
    # the fixed shoal is not a parameter; barrier positions stay near the centreline
    targets = {(b.kind, b.name, b.field) for b in m.bindings}
    assert ("barrier", "S", "x") not in targets
    for p, b in zip(m.space.parameters, m.bindings):
        if b.kind == "barrier" and b.field == "x":
            assert -400 <= p.low and p.high <= 400
        if b.kind == "transmission" and b.field == "x":
            assert p.high + m.transmission.width / 2 <= 0  # western half


def test_priority_is_a_permutation_of_the_area_names():
    for name in ("uuv18", "range2017"):
        m = load(name)
        (i,) = [k for k, b in enumerate(m.bindings) if b.field == "priority"]
        p = m.space.parameters[i]
        assert isinstance(p, Permutation) and sorted(p.items) == sorted(a.name for a in m.mission_areas)
        assert m.bindings[i] == Binding(p.name, "mission_areas", None, "priority")
        assert m.space.slice_of(p.name).stop - m.space.slice_of(p.name).start == 3
        orders = {s[p.name] for s in m.space.decode(np.random.default_rng(0).random((200, m.dim)))}
        assert len(orders) == 6


def test_range2017_and_imitation7_specifics():
    r = load("range2017")
    assert not r.obstacles and not r.barriers
    assert {z.name for z in r.nogo} == {"NG", "BN1", "BN2"}
    assert [b for b in r.bindings if b.kind == "vehicle"] == [
        Binding("start_battery", "vehicle", None, "start_battery")
    ]
    assert r.time_limit_s <= 2700

    m = load("imitation7")
    assert m.mission_requires == ("waypoints",)
    assert len(m.waypoints) == 1 and m.transmission is None and not m.mission_areas
    assert [b.field for b in m.bindings] == ["x", "y"] * 3 + ["start_battery"]
    names = [n.name for n in tree(m).nodes()]
    assert not any(n.startswith(("barrier ", "no-go area ", "mission area ")) for n in names)  # zero copies vanish
    assert "transmission" not in metric_names(m)


# --------------------------------------------------------------------------- bad files
BASE = """
[mission]
name = "tiny"
origin = { lat = 47.7, lon = -122.62 }
start_time_s = 0
time_limit_s = 600

[operational_area]
x = 0
y = 0
width = 1000
height = 1000

[launch]
x = 0
y = -400

[recovery]
x = 20
y = -400

[[mission_areas]]
name = "A"
x = 200
y = 200
dwell_s = 60

[[mission_areas]]
name = "B"
x = -200
y = 200
dwell_s = 60

[[nogo]]
name = "N1"
x = 300
y = -300

[[parameters]]
name = "nogo_x"
kind = "continuous"
low = 0
high = 400
target = "nogo.N1.x"

[[parameters]]
name = "priority"
kind = "permutation"
items = ["A", "B"]
target = "mission_areas.priority"

[score_tree]
name = "root"
scores = ["mission_success", "safety_success"]

[[score_tree.children]]
name = "objectives"
scores = ["waypoints", "mission_areas", "mission_time", "collisions", "nogo_areas", "operational_area",
          "recovery", "surfacing"]

[[score_tree.children.children]]
for_each = "area"
scores = ["area.{name}"]

[[score_tree.children.children.children]]
scores = ["area.{name}.dwell_s", "area.{name}.entry_s", "area.{name}.done_s", "area.{name}.closest_m",
          "area.{name}.order"]

[[score_tree.children.children]]
for_each = "nogo"
scores = ["nogo.{name}", "nogo.{name}.closest_m", "nogo.{name}.inside_s", "nogo.{name}.time_s"]

[[score_tree.children.children]]
name = "leaves"
scores = ["mission.time_s", "mission.battery_left", "mission.distance_m", "mission.return_reason",
          "operational_area.margin_m", "recovery.distance_m", "recovery.time_s", "recovery.battery",
          "surfacing.outside_s", "surfacing.count"]
"""


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def mutate(old: str, new: str) -> str:
    assert old in BASE, old
    return BASE.replace(old, new, 1)


def test_base_mission_loads(tmp_path):
    m = load_mission(write(tmp_path, BASE, "tiny.toml"))
    assert m.dim == 3 and m.priority == ("A", "B")
    assert m.mission_requires == ("mission_areas", "mission_time")  # no transmission in the file
    assert m.waypoint_radius == 25.0 and m.dt == 2.0 and m.recovery_radius == 15.0
    assert (m.nogo[0].width, m.nogo[0].height) == (400, 500)
    assert isinstance(m.space.parameters[0], Continuous)


def test_scenarios_leave_the_search_at_the_range_s_resolution(tmp_path):
    """A position snaps to 0.1 m unless the file gives its own step; the search itself stays continuous."""
    import numpy as np

    U = np.random.default_rng(3).random((50, 3))
    space = load_mission(write(tmp_path, BASE, "tiny.toml")).space
    assert space.parameters[0].resolution == 0.1
    np.testing.assert_allclose([s["nogo_x"] for s in space.decode(U)], U[:, 0] * 400, rtol=1e-12)
    x = np.array([s["nogo_x"] for s in space.decode(space.snap(U))])
    np.testing.assert_array_equal(x, np.round(U[:, 0] * 400, 1))
    assert all(len(repr(float(v)).split(".")[1]) <= 1 for v in x)  # written as the range reads them: 364.1
    coarse = load_mission(write(tmp_path, mutate("low = 0\nhigh = 400", "low = 0\nhigh = 400\nresolution = 5")))
    x5 = np.array([s["nogo_x"] for s in coarse.space.decode(coarse.space.snap(U))])
    np.testing.assert_allclose(x5 % 5, 0, atol=1e-9)
    assert np.max(np.abs(x5 - U[:, 0] * 400)) <= 2.5 + 1e-9


BAD = {
    "unknown key": (
        mutate("time_limit_s = 600", 'time_limit_s = 600\ncolour = "red"'),
        "mission.colour",
        "unknown key",
    ),
    "missing field": (mutate("time_limit_s = 600\n", ""), "mission.time_limit_s", "missing"),
    "low >= high": (mutate("low = 0\nhigh = 400", "low = 400\nhigh = 100"), "parameters[0].low", "must be < high"),
    "missing element": (
        mutate('target = "nogo.N1.x"', 'target = "nogo.Z.x"'),
        "parameters[0].target",
        "unknown element 'nogo.Z' (known no-go areas: N1)",
    ),
    "permutation items": (
        mutate('items = ["A", "B"]', 'items = ["A", "C"]'),
        "parameters[1].items",
        "mission-area names",
    ),
    "unknown metric": (
        mutate('scores = ["waypoints",', 'scores = ["waypoint",'),
        "score_tree.children[0].scores[0]",
        "unknown metric 'waypoint'",
    ),
    "duplicate element": (mutate('name = "B"', 'name = "A"'), "mission_areas[1].name", "duplicate element name"),
    "resolution too coarse": (
        mutate("low = 0\nhigh = 400", "low = 0\nhigh = 400\nresolution = 300"),
        "parameters[0].resolution",
        "at least three settable values",
    ),
    "resolution not positive": (
        mutate("low = 0\nhigh = 400", "low = 0\nhigh = 400\nresolution = 0"),
        "parameters[0].resolution",
        "finest step",
    ),
    "position outside": (
        mutate("low = 0\nhigh = 400", "low = 0\nhigh = 900"),
        "parameters[0].high",
        "operational area",
    ),
    "for_each kind": (
        mutate('for_each = "area"', 'for_each = "areas"'),
        "score_tree.children[0].children[0].for_each",
        "unknown element kind 'areas'",
    ),
    "TOML syntax": (mutate("time_limit_s = 600", "time_limit_s = = 600"), "TOML syntax", "line 6"),
    "non-finite": (mutate("time_limit_s = 600", "time_limit_s = inf"), "mission.time_limit_s", "not finite"),
    "wrong type": (mutate("dwell_s = 60", 'dwell_s = "60"'), "mission_areas[0].dwell_s", "expected a number"),
    "missing column": (
        mutate('"surfacing.outside_s", "surfacing.count"', '"surfacing.outside_s"'),
        "score_tree:",
        "'surfacing.count'",
    ),
    "duplicate column": (
        mutate(
            '"surfacing.outside_s", "surfacing.count"', '"surfacing.outside_s", "surfacing.count", "mission.time_s"'
        ),
        "score_tree.children[0].children[2].scores[10]",
        "appears twice",
    ),
    "name outside for_each": (
        mutate('name = "leaves"\nscores = ["mission.time_s"', 'name = "leaves"\nscores = ["{name}"'),
        "score_tree.children[0].children[2].scores[0]",
        "outside a for_each",
    ),
    "unknown section": (BASE + "\n[vehicel]\nbattery_wh = 10\n", "vehicel", "did you mean 'vehicle'"),
    "unknown vehicle field": (BASE + "\n[vehicle]\nbattery_kwh = 10\n", "vehicle.battery_kwh", "allowed keys"),
    "duplicate parameter": (
        mutate('name = "priority"', 'name = "nogo_x"'),
        "parameters[1].name",
        "duplicate parameter name",
    ),
    "element on unnamed target": (
        mutate('target = "nogo.N1.x"', 'target = "vehicle.V.start_battery"'),
        "parameters[0].target",
        "takes no element name",
    ),
    "bad field": (mutate('target = "nogo.N1.x"', 'target = "nogo.N1.width"'), "parameters[0].target", "settable: x, y"),
    "priority not permutation": (
        mutate('kind = "permutation"', 'kind = "categorical"'),
        "parameters[1]",
        "permutation",
    ),
    "mission priority": (
        mutate("time_limit_s = 600", 'time_limit_s = 600\npriority = ["A", "A"]'),
        "mission.priority",
        "exactly once",
    ),
    "requires missing objective": (
        mutate("time_limit_s = 600", 'time_limit_s = 600\nrequires = ["transmission"]'),
        "mission.requires",
        "[transmission]",
    ),
    "element outside": (mutate("x = 300\ny = -300", "x = 3000\ny = -300"), "nogo[0]", "outside the operational area"),
    # a calibrated vehicle block that no vehicle could have: a negative draw, a curve that falls
    "negative drag": (BASE + "\n[vehicle]\ndrag_w = -5.0\n", "vehicle.drag_w", "negative power"),
    "negative hotel": (BASE + "\n[vehicle]\nhotel_w = -1.0\n", "vehicle.hotel_w", "negative power"),
    "falling speed curve": (
        BASE + "\n[vehicle]\nspeed_curve = [[1.0, 1.0], [2.0, 1.9], [3.0, 1.7]]\n",
        "vehicle.speed_curve[2]",
        "non-decreasing",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_files_name_the_file_and_the_field(tmp_path, case):
    text, field, words = BAD[case]
    path = write(tmp_path, text)
    with pytest.raises(MissionFileError) as info:
        load_mission(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: "), msg
    assert field in msg, msg
    assert words in msg, msg
    assert "\n" not in msg and ";" in msg  # one line, with a fix after the problem
    assert isinstance(info.value, FileFormatError) and isinstance(info.value, ValueError)


def test_missing_file_is_a_mission_file_error(tmp_path):
    with pytest.raises(MissionFileError, match="nope.toml"):
        load_mission(tmp_path / "nope.toml")


# --------------------------------------------------------------------------- geo
def test_local_frame_round_trip_and_scale():
    f = LocalFrame(47.70, -122.62)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-10_000, 10_000, (2, 500))
    lat, lon = f.to_latlon(x, y)
    x2, y2 = f.to_local(lat, lon)
    assert np.max(np.abs(x2 - x)) < 1e-6 and np.max(np.abs(y2 - y)) < 1e-6
    assert f.to_local(47.70, -122.62) == (0.0, 0.0)
    _, north = f.to_local(48.70, -122.62)
    assert north == pytest.approx(111_200, abs=200)  # ~111.2 km per degree of latitude
    assert f.to_local(47.71, -122.62)[1] == pytest.approx(math.radians(0.01) * f.meridian_radius, abs=0.01)
    east, _ = f.to_local(47.70, -121.62)
    assert east == pytest.approx(math.radians(1) * f.prime_vertical_radius * math.cos(math.radians(47.7)), rel=1e-3)
    assert isinstance(f.to_latlon(10.0, 20.0)[0], float)
    assert f.to_latlon(np.zeros((3, 4)), 0.0)[0].shape == (3, 4)


def test_local_frame_distances_match_the_ellipsoid_within_a_few_cm():
    """Plane distances agree with straight-line (ECEF chord) distances out to 10 km."""
    a, f_ = 6_378_137.0, 1 / 298.257223563
    e2 = f_ * (2 - f_)

    def ecef(lat, lon):
        phi, lam = np.radians(lat), np.radians(lon)
        n = a / np.sqrt(1 - e2 * np.sin(phi) ** 2)
        return np.stack([n * np.cos(phi) * np.cos(lam), n * np.cos(phi) * np.sin(lam), n * (1 - e2) * np.sin(phi)], -1)

    frame = LocalFrame(47.70, -122.62)
    rng = np.random.default_rng(2)
    ang = rng.uniform(0, 2 * np.pi, 200)
    x, y = 7000 * np.cos(ang), 7000 * np.sin(ang)
    lat, lon = frame.to_latlon(x, y)
    chord = np.linalg.norm(ecef(lat, lon) - ecef(47.70, -122.62), axis=1)
    assert np.max(np.abs(np.hypot(x, y) - chord)) < 0.05
    # pairs of points on opposite sides: 14 km apart
    lat2, lon2 = frame.to_latlon(-x, -y)
    chord2 = np.linalg.norm(ecef(lat, lon) - ecef(lat2, lon2), axis=1)
    assert np.max(np.abs(14_000 - chord2)) < 0.2


def test_degE7_round_trip():
    v = np.array([47.7, -122.62, 0.0, 179.9999999, -90.0])
    e7 = to_degE7(v)
    assert e7.dtype == np.int32
    assert list(e7[:2]) == [477_000_000, -1_226_200_000]
    assert np.max(np.abs(from_degE7(e7) - v)) <= 0.5e-7
    with pytest.raises(ValueError):
        to_degE7(200.0)
    with pytest.raises(ValueError):
        LocalFrame(91.0, 0.0)


# --------------------------------------------------------------------------- imitation7_dense
def test_imitation7_dense_keeps_the_study_and_makes_safety_failures_matter():
    """The variant has imitation7's 7 parameters and score tree, and a quarter of its scenarios fail safety."""
    from scipy.stats import qmc

    import sim.uuv
    from sim.uuv.scoring import MODE_NAMES

    m, base = load("imitation7_dense"), load("imitation7")
    assert m.name == "imitation7_dense"
    assert m.space.names == base.space.names and m.bindings == base.bindings
    assert [type(p) for p in m.space.parameters] == [type(p) for p in base.space.parameters]
    assert m.score_tree == base.score_tree and metric_names(m) == metric_names(base)
    res = sim.uuv.simulate(m, qmc.Sobol(7, seed=0).random(256))
    assert res.valid.mean() >= 0.8
    share = {k: np.mean(res.modes[res.valid] == i) for i, k in enumerate(MODE_NAMES)}
    assert share["TF"] + share["MS"] >= 0.15, share  # 26% (2,048 points: 27%; imitation7: 2%)
    assert share["SS"] > 0 and share["TS"] > 0, share  # the battery-abort boundary remains
    recovery = res.scores[res.valid, res.names.index("recovery")]
    assert np.mean(recovery < 0.5) >= 0.15  # detours round the obstacles drain the battery before home
