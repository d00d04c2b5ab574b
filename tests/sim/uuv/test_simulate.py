"""The UUV simulator: dynamics, each behaviour's trigger, scoring rules, validity, determinism."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from sim.uuv.autonomy import RETURN_COMPLETE, RETURN_FUEL, RETURN_TIME
from sim.uuv.metrics import metric_names
from sim.uuv.mission import Vehicle
from sim.uuv.navigation import Navigation, filterpy_filter
from sim.uuv.simulate import TRAJECTORY_FIELDS
from sim.uuv.vehicle import VehicleState, propulsion_power, step_vehicle
from tests.support.uuvworld import Current, Rect, Transmission, Triangle, area, mission, vehicle

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def run(m, **kw):
    return sim.uuv.simulate(m, np.zeros((1, m.dim)), trajectories=True, **kw)


def col(result, name):
    return float(result.column(name)[0])


# -- dynamics -------------------------------------------------------------------------


def test_vehicle_turns_at_its_rate_limit_and_settles_on_command():
    spec = Vehicle()
    s = VehicleState.at_rest(np.zeros(1), np.zeros(1), np.zeros(1), np.full(1, 1000.0))
    headings = []
    for _ in range(60):
        step_vehicle(s, spec, np.full(1, np.pi / 2), np.full(1, 2.0), np.zeros(1), np.zeros(1), 1.0, np.ones(1, bool))
        headings.append(s.heading[0])
    rates = np.abs(np.diff(np.degrees(headings)))
    assert rates.max() <= spec.max_turn_rate_dps + 1e-9  # never faster than the rate limit
    assert abs(np.degrees(s.heading[0]) - 90.0) < 1.0 and abs(s.surge[0] - 2.0) < 0.01
    assert s.x[0] > 50 and abs(s.y[0]) < 40  # ends up going east


def test_power_grows_with_the_cube_of_speed_and_drains_the_battery():
    spec = Vehicle()
    p2, p3 = propulsion_power(spec, np.array([2.0, 3.0]))
    assert p3 - spec.hotel_w == pytest.approx((p2 - spec.hotel_w) * 1.5**3)
    s = VehicleState.at_rest(np.zeros(2), np.zeros(2), np.zeros(2), np.full(2, 100.0))
    for _ in range(100):
        step_vehicle(s, spec, np.zeros(2), np.array([1.0, 3.0]), np.zeros(2), np.zeros(2), 1.0, np.ones(2, bool))
    assert s.energy_wh[1] < s.energy_wh[0] < 100.0


def test_current_carries_a_vehicle_and_crabbing_cancels_it():
    drift = mission(current=Current(speed=1.0, direction_deg=90.0, peak_hour=0.0, perturbation=0.0))
    r = run(drift)
    track = r.trajectories[0]
    assert col(r, "waypoint.0") == 1.0
    assert np.abs(track[:, 1]).max() < 25.0  # a 1 m/s cross current, yet the track stays within 25 m
    s = VehicleState.at_rest(np.zeros(1), np.zeros(1), np.zeros(1), np.full(1, 100.0))
    for _ in range(10):  # without crabbing the same current sets the vehicle 10 m east in 10 s
        step_vehicle(s, Vehicle(), np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1), 1.0, np.ones(1, bool))
    assert s.x[0] == pytest.approx(10.0)


# -- behaviours -----------------------------------------------------------------------


def test_plain_mission_reaches_the_waypoint_and_recovers():
    r = run(mission())
    assert r.modes[0] == 3 and col(r, "waypoint.0") == 1.0 and col(r, "recovery") == 1.0
    assert col(r, "mission.return_reason") == RETURN_COMPLETE
    assert 700 < col(r, "mission.time_s") < 1000  # 1.6 km at 2 m/s plus turns


def test_sonar_sees_an_obstacle_in_the_path_and_avoidance_clears_it():
    r = run(mission(obstacles=(Triangle("O1", 0.0, -400.0, 50.0),)))
    assert col(r, "obstacle.O1.detected_s") < col(r, "waypoint.0.time_s")
    assert 0 < col(r, "obstacle.O1.closest_m") < 100 and col(r, "collisions") == 1.0
    assert col(r, "waypoint.0") == 1.0


def test_barrier_across_the_path_is_a_local_minimum_and_the_waypoint_is_abandoned():
    centred = run(mission(barriers=(Rect("B", 0.0, -300.0, 700.0, 40.0),)))
    assert col(centred, "waypoint.0.aborted") == 1.0 and col(centred, "waypoint.0") == 0.0
    assert col(centred, "collisions") == 1.0 and col(centred, "recovery") == 1.0
    offset = run(mission(barriers=(Rect("B", 200.0, -300.0, 700.0, 40.0),)))  # a way round the west end
    assert col(offset, "waypoint.0") == 1.0 and col(offset, "waypoint.0.aborted") == 0.0


def test_waypoint_close_to_a_no_go_area_is_aborted():
    r = run(mission(nogo=(Rect("N", 60.0, 0.0, 40.0, 100.0),)))
    assert col(r, "waypoint.0.aborted") == 1.0 and col(r, "waypoint.0") == 0.0
    assert col(r, "nogo.N") == 1.0 and col(r, "nogo.N.closest_m") > 0
    far = run(mission(nogo=(Rect("N", 200.0, 0.0, 40.0, 100.0),)))
    assert col(far, "waypoint.0.aborted") == 0.0 and col(far, "waypoint.0") == 1.0


def test_low_fuel_turns_the_vehicle_home_before_the_survey():
    areas = dict(mission_areas=(area("A", 0.0, 600.0),), priority=("A",), mission_requires=("mission_areas",))
    full = run(mission(vehicle=vehicle(start_battery=0.2), **areas))
    low = run(mission(vehicle=vehicle(start_battery=0.02), **areas))
    assert col(full, "area.A") == 1.0 and col(full, "mission.return_reason") == RETURN_COMPLETE
    assert col(low, "mission.return_reason") == RETURN_FUEL
    assert col(low, "area.A") == 0.0 and col(low, "recovery") == 1.0 and low.modes[0] == 1  # SS


def test_survey_loiters_for_the_dwell_time_in_priority_order():
    m = mission(
        mission_areas=(area("A", -300.0, 300.0, dwell=90.0), area("B", 300.0, 300.0, dwell=60.0)),
        priority=("B", "A"),
        mission_requires=("mission_areas",),
    )
    r = run(m)
    assert col(r, "mission_areas") == 1.0
    assert col(r, "area.B.order") == 1 and col(r, "area.A.order") == 2
    assert col(r, "area.A.dwell_s") >= 90.0 and col(r, "area.B.dwell_s") >= 60.0
    assert col(r, "area.B.done_s") < col(r, "area.A.entry_s")


def test_transmission_surfaces_inside_the_area_only_while_the_window_is_open():
    tx = Transmission("TX", -400.0, -400.0, 300.0, 300.0, 300.0, 1200.0, 120.0)
    r = run(mission(transmission=tx, mission_requires=("transmission",)))
    track = r.trajectories[0]
    surfaced_t = track[track[:, 5] > 0, 0]
    assert col(r, "transmission") == 1.0 and col(r, "surfacing.outside_s") == 0.0
    assert surfaced_t.min() >= 300.0 and surfaced_t.max() < 1500.0
    assert col(r, "transmission.time_s") - 300.0 >= 120.0 - 1e-9
    closed = run(
        mission(
            transmission=dataclasses.replace(tx, window_start_s=10.0, window_length_s=30.0),
            mission_requires=("transmission",),
        )
    )
    assert col(closed, "transmission") == 0.0 and closed.modes[0] == 1  # the window closed before arrival


def test_early_transmission_comes_before_the_survey():
    tx = Transmission("TX", -400.0, -400.0, 300.0, 300.0, 0.0, 900.0, 120.0)
    areas = (area("A", 400.0, 400.0),)
    r = run(
        mission(
            transmission=tx,
            mission_areas=areas,
            priority=("A",),
            waypoints=(),
            mission_requires=("mission_areas", "transmission"),
        )
    )
    assert col(r, "transmission.time_s") < col(r, "area.A.entry_s")


# -- scoring rules --------------------------------------------------------------------


def test_entering_a_no_go_area_fails_safety_but_the_run_goes_on():
    # home lies beyond a no-go area: at critical battery the vehicle goes straight through it
    geometry = dict(recovery=(0.0, 600.0), waypoints=(), nogo=(Rect("N", 200.0, -300.0, 600.0, 60.0),))
    critical = run(mission(vehicle=vehicle(start_battery=0.03), **geometry))
    assert col(critical, "nogo.N") == 0.0 and col(critical, "nogo.N.inside_s") > 0
    assert col(critical, "safety_success") == 0.0 and col(critical, "recovery") == 1.0  # the run went on
    healthy = run(mission(vehicle=vehicle(start_battery=0.2), **geometry))
    assert col(healthy, "nogo.N") == 1.0 and col(healthy, "recovery") == 1.0  # round the west end


def test_leaving_the_operational_area_ends_the_run_as_a_safety_failure():
    # a 3.5 m/s current beats the vehicle's 3 m/s, however it keeps off the edge
    r = run(mission(current=Current(speed=3.5, direction_deg=90.0, peak_hour=0.0, perturbation=0.0)))
    assert col(r, "operational_area") == 0.0 and col(r, "operational_area.margin_m") < 0
    assert col(r, "safety_success") == 0.0 and col(r, "mission.time_s") < 3600.0  # the run ended there
    assert r.trajectories[0][-1, 0] == col(r, "mission.time_s")
    calm = run(mission(waypoints=((0.0, 1500.0),)))  # a waypoint outside: the autonomy stays inside
    assert col(calm, "operational_area") == 1.0 and col(calm, "waypoint.0") == 0.0


def test_time_limit_turns_the_vehicle_back_and_fails_the_mission_when_home_is_too_far():
    short = run(mission(time_limit_s=300.0))  # no time for the waypoint: turn back, get home in time
    assert col(short, "mission.return_reason") == RETURN_TIME and col(short, "waypoint.0") == 0.0
    assert col(short, "mission_time") == 1.0 and col(short, "recovery") == 1.0 and short.modes[0] == 1
    stranded = run(mission(time_limit_s=300.0, recovery=(0.0, 800.0)))  # 1.6 km home in 5 minutes
    assert col(stranded, "mission_time") == 0.0 and col(stranded, "recovery") == 0.0 and stranded.modes[0] == 0


def test_scores_are_finite_and_named_for_every_column():
    m = sim.uuv.load_mission(EXAMPLES / "uuv18.toml")
    r = sim.uuv.simulate(m, np.random.default_rng(0).random((64, m.dim)))
    assert r.scores.shape == (64, len(metric_names(m))) and r.names == metric_names(m)
    assert np.all(np.isfinite(r.scores[r.valid])) and np.all(np.isnan(r.scores[~r.valid]))
    binary = [i for i, t in enumerate(r.output_types) if t == "binary"]
    assert set(np.unique(r.scores[r.valid][:, binary])) <= {0.0, 1.0}


# -- validity, determinism, batch == single -------------------------------------------


def test_invalid_scenarios_are_reported_not_simulated():
    m = mission(obstacles=(Triangle("O1", 0.0, -820.0, 50.0),))  # on the recovery point
    r = sim.uuv.simulate(m, np.zeros((2, m.dim)))
    assert not r.valid.any() and np.all(np.isnan(r.scores)) and np.all(r.modes == -1)
    assert "recovery point" in r.invalid_reason[0]


def test_bad_input_names_the_field():
    m = mission()
    with pytest.raises(ValueError, match="X: expected unit-cube rows of shape"):
        sim.uuv.simulate(m, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="unit cube"):
        sim.uuv.simulate(m, np.full((1, 1), 1.5))


@pytest.mark.parametrize(
    "name",
    ["range2017", pytest.param("uuv18", marks=pytest.mark.slow), "imitation7"],  # uuv18: about 16 s
)
def test_a_scenario_scores_the_same_alone_as_in_a_batch(name):
    m = sim.uuv.load_mission(EXAMPLES / f"{name}.toml")
    X = np.random.default_rng(1).random((200, m.dim))
    batch = sim.uuv.simulate(m, X)
    for i in np.flatnonzero(batch.valid)[:6]:
        alone = sim.uuv.simulate(m, X[i : i + 1])
        np.testing.assert_array_equal(alone.scores[0], batch.scores[i])


def test_stochastic_runs_are_seeded_and_independent_of_the_batch():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(2).random((120, m.dim))
    a = sim.uuv.simulate(m, X, seed=5, stochastic=True)
    b = sim.uuv.simulate(m, X, seed=5, stochastic=True)
    c = sim.uuv.simulate(m, X, seed=6, stochastic=True)
    det = sim.uuv.simulate(m, X)
    np.testing.assert_array_equal(a.scores, b.scores)
    assert np.any(a.scores[a.valid] != c.scores[c.valid])  # another seed, other runs
    assert np.any(a.scores[a.valid] != det.scores[det.valid])  # noise is on
    i = int(np.flatnonzero(a.valid)[3])
    np.testing.assert_array_equal(sim.uuv.simulate(m, X[i : i + 1], seed=5, stochastic=True).scores[0], a.scores[i])


def test_navigation_filter_matches_filterpy():
    spec, dt = Vehicle(), 2.0
    rng = np.random.default_rng(3)
    nav = Navigation(1, spec)
    kf = filterpy_filter(spec, dt)
    for k in range(200):
        surfaced = np.array([k % 50 > 40])
        z = rng.standard_normal((1, 4))
        nav.step(dt, surfaced, z)
        kf.predict()
        if surfaced[0]:
            kf.update(np.zeros(2))
        assert nav.var[0] == pytest.approx(kf.P[0, 0], rel=1e-9)


def test_trajectories_cover_the_run():
    r = run(mission())
    track = r.trajectories[0]
    assert track.shape[1] == len(TRAJECTORY_FIELDS) and track[-1, 0] == pytest.approx(col(r, "mission.time_s"))
    assert np.hypot(track[-1, 1] - 0.0, track[-1, 2] + 820.0) <= 15.0 + 1e-6


def test_a_mission_study_feeds_the_sub_boundary_tree():
    import rapt

    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(4).random((1024, m.dim))
    r = sim.uuv.simulate(m, X)
    tree = rapt.subboundary_tree(X[r.valid], r.scores[r.valid], m.score_tree, output_types=r.output_types)
    assert len(tree.levels) == 4 and tree.n_clusters(0) >= 3
    roots = r.scores[r.valid][:, :2]
    assert tree.n_clusters(0) == len(np.unique(roots, axis=0))  # level 0 = the performance modes
    rec = tree.reconstruct(r.names.index("recovery"), 0.0)  # every run that failed to get home
    assert rec.members.size == int((r.column("recovery")[r.valid] == 0).sum())
    inside = np.isin(np.arange(r.valid.sum()), rec.members)
    assert len(rec) > 0 and np.all(inside[rec.i]) and not np.any(inside[rec.j])


def _simulate_alone(path, row):
    m = sim.uuv.load_mission(path)
    return sim.uuv.simulate(m, row[None, :]).scores[0]


def test_a_single_vehicle_in_its_own_process_scores_as_in_the_batch():
    import concurrent.futures as cf
    import multiprocessing as mp

    path = EXAMPLES / "range2017.toml"
    m = sim.uuv.load_mission(path)
    X = np.random.default_rng(8).random((64, m.dim))
    batch = sim.uuv.simulate(m, X)
    rows = np.flatnonzero(batch.valid)[:4]
    with cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        alone = list(pool.map(_simulate_alone, [path] * rows.size, [X[i] for i in rows]))
    for i, scores in zip(rows, alone):
        np.testing.assert_array_equal(scores, batch.scores[i])


def test_a_run_rescored_from_its_telemetry_track_matches_the_batch():
    from sim.uuv.replay import score_track

    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(9).random((40, m.dim))
    r = sim.uuv.simulate(m, X, trajectories=True)
    names = r.names
    for i in np.flatnonzero(r.valid)[:15]:
        aborted = [r.scores[i, names.index(f"waypoint.{w}.aborted")] > 0 for w in range(len(m.waypoints))]
        again = score_track(
            m, X[i], r.trajectories[i][:, :6], aborted, int(r.scores[i, names.index("mission.return_reason")])
        )
        np.testing.assert_array_equal(again, r.scores[i])


def test_each_obstacle_is_a_triangle_of_its_own_side():
    """Sides per obstacle: any number of obstacles, each as large as its own entry (not its corner's)."""
    from sim.uuv.geometry import triangle_vertices

    sides = np.array([40.0, 80.0, 120.0, 200.0, 10.0])
    cx, cy = np.zeros((2, 5)), np.zeros((2, 5))
    tri = triangle_vertices(cx, cy, sides)
    assert tri.shape == (2, 5, 3, 2)
    edges = np.linalg.norm(tri - np.roll(tri, -1, axis=2), axis=-1)  # (2, 5, 3) edge lengths
    np.testing.assert_allclose(edges, np.broadcast_to(sides[None, :, None], edges.shape))
    np.testing.assert_allclose(triangle_vertices(cx, cy, 80.0), triangle_vertices(cx, cy, np.full(5, 80.0)))
