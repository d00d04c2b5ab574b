"""Imitation-learning surrogates (chapter 6): features, learners, files, and the bus."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from rapt.errors import FileFormatError, MissingFileError, StudyMismatchError
from rapt.imitation.dagger import Trajectory
from rapt.imitation.policies import MLPPolicy
from sim.uuv.imitation.features import action_command, expert_action, feature_spec, features
from sim.uuv.imitation.rollouts import annotated_runs
from sim.uuv.imitation.surrogate import Surrogate
from sim.uuv.scenario import make_scenarios
from sim.uuv.simulate import observation
from sim.uuv.sonar import scan
from sim.uuv.world import World
from tests.support.hand_policy import steering_policy as _steering_policy

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
IMITATION7 = sim.uuv.load_mission(EXAMPLES / "imitation7.toml")
SPEC = feature_spec(IMITATION7)  # the expert's remembered contacts
SCAN = feature_spec(IMITATION7, "scan")  # section 6.5.3's 360-degree scan
NO_TRIANGLES = np.zeros((1, 0, 3, 2))


def _scene(x, y, heading, barriers, battery=0.5, t=0.0, waypoint=(0.0, 350.0), pending=True):
    h = np.array([heading])
    r = scan(np.array([x]), np.array([y]), h, NO_TRIANGLES, np.array([barriers], float), 100.0)
    target = (np.array([waypoint[0]]), np.array([waypoint[1]]), np.array([pending]))
    return features(SCAN, IMITATION7, t, np.array([x]), np.array([y]), h, np.array([battery]), r, target)[0], r[0]


def test_features_of_a_hand_built_scene():
    # vehicle at the origin heading north; a wall 10 m ahead (x -5..5, y 10..20); waypoint 350 m north
    f, ranges = _scene(0.0, 0.0, 0.0, [[-5, 5, 10, 20]], battery=0.25, t=600.0)
    assert f.shape == (SCAN.size,) == (368,) and f.dtype == np.float32
    assert np.all(f >= -1) and np.all(f <= 1)
    names = SCAN.names()
    col = {n: i for i, n in enumerate(names)}
    assert f[col["fuel"]] == pytest.approx(-0.5)
    assert f[col["waypoint_fwd"]] == pytest.approx(1.0) and f[col["waypoint_stbd"]] == pytest.approx(0.0, abs=1e-6)
    assert f[col["waypoint_distance"]] == pytest.approx(2 * 350 / SCAN.map_scale_m - 1, abs=1e-6)
    # recovery (0, -400) is dead astern
    assert f[col["recovery_fwd"]] == pytest.approx(-1.0) and f[col["recovery_distance"]] > f[col["waypoint_distance"]]
    assert f[col["clock"]] == pytest.approx(2 * 600 / IMITATION7.time_limit_s - 1)
    # the scan: 10 m dead ahead, 10/cos(20 deg) at 20 degrees, nothing abeam or astern
    assert ranges[0] == 10.0 and ranges[20] == pytest.approx(10 / np.cos(np.deg2rad(20)), abs=0.006)
    assert ranges[90] == ranges[180] == 100.01
    assert f[col["sonar_0"]] == pytest.approx(2 * 10 / 100 - 1) and f[col["sonar_180"]] == 1.0
    # turn the vehicle east: the waypoint is now to port, the wall on the port beam (beam 270)
    f, ranges = _scene(0.0, 0.0, np.pi / 2, [[-5, 5, 10, 20]])
    assert f[col["waypoint_fwd"]] == pytest.approx(0.0, abs=1e-6) and f[col["waypoint_stbd"]] == pytest.approx(-1.0)
    assert ranges[270] == 10.0 and ranges[0] == 100.01
    # all waypoints reached: the waypoint features read zero; inside an obstacle every beam reads 0
    f, _ = _scene(0.0, 0.0, 0.0, [[-5, 5, 10, 20]], pending=False)
    assert np.all(f[1:4] == 0)
    _, ranges = _scene(0.0, 15.0, 0.0, [[-5, 5, 10, 20]])
    assert np.all(ranges == 0)


def test_actions_round_trip_through_the_vehicle_frame():
    rng = np.random.default_rng(0)
    heading = rng.uniform(-np.pi, np.pi, 50)
    cmd = rng.uniform(-np.pi, np.pi, 50)
    speed = rng.uniform(0, SPEC.max_speed, 50)
    a = expert_action(SPEC, heading, cmd, speed)
    np.testing.assert_allclose(np.hypot(a[:, 0], a[:, 1]), 1.0, rtol=1e-6)  # a direction: its length is 1
    h2, s2 = action_command(SPEC, heading, a)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h2 - cmd))), 0, atol=1e-5)
    np.testing.assert_allclose(s2, speed, rtol=1e-5)
    # straight ahead at cruise, still pursuing the waypoint: direction (1, 0), goal -1, speed cruise / max;
    # hard to starboard is positive y
    np.testing.assert_allclose(expert_action(SPEC, [0.0], [0.0], [2.0]), [[1.0, 0.0, -1.0, 2 / 3]], atol=1e-7)
    assert expert_action(SPEC, [0.0], [np.pi / 2], [3.0])[0, 1] == pytest.approx(1.0)
    assert expert_action(SPEC, [0.0, 0.0], [0.0, 0.0], [1.0, 1.0], home=[True, False])[:, 2].tolist() == [1, -1]


# -- surrogate files --------------------------------------------------------------------------------
def test_surrogate_files_round_trip_and_refuse_another_mission(tmp_path):
    sur = Surrogate.for_mission(IMITATION7, _steering_policy(), {"method": "hand-made", "runs": 0}, goal_threshold=-0.4)
    path = sur.save(tmp_path / "s.npz")
    back = Surrogate.load(path, IMITATION7)
    F = np.random.default_rng(0).uniform(-1, 1, (10, SPEC.size)).astype(np.float32)
    np.testing.assert_array_equal(back.policy(F), sur.policy(F))
    assert back.spec == SPEC and back.training["method"] == "hand-made" and back.goal_threshold == -0.4
    other = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    with pytest.raises(StudyMismatchError, match=r"trained for mission 'imitation7' \(\w+\), not for 'range2017'"):
        Surrogate.load(path, other)
    edited = dataclasses.replace(IMITATION7, vehicle=dataclasses.replace(IMITATION7.vehicle, battery_wh=250.0))
    with pytest.raises(StudyMismatchError, match="not for 'imitation7'"):
        Surrogate.load(path, edited)
    with pytest.raises(MissingFileError, match="does not exist"):  # a FileNotFoundError, as before
        Surrogate.load(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match="not a surrogate file"):
        Surrogate.load(tmp_path / "junk.npz")
    with np.load(path) as z:  # a surrogate of the last format (a velocity vector, no speed output)
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    arrays["header"] = np.array(json.dumps({**header, "format": "rapt.surrogate/2"}))
    np.savez(tmp_path / "old.npz", **arrays)
    with pytest.raises(FileFormatError, match=r"\(rapt.surrogate/2\) observes a velocity vector .*; retrain"):
        Surrogate.load(tmp_path / "old.npz", IMITATION7)
    # a surrogate of the last format saw a scan without memory: another observation model, refused
    arrays["header"] = np.array(json.dumps({**header, "format": "rapt.surrogate/3"}))
    np.savez(tmp_path / "scan3.npz", **arrays)
    with pytest.raises(FileFormatError, match=r"observes a 360-degree scan with no memory of contacts.*retrain"):
        Surrogate.load(tmp_path / "scan3.npz", IMITATION7)
    # a scan-fed surrogate of this format, edited to claim the contacts: its features do not match
    scan_sur = Surrogate.for_mission(IMITATION7, _steering_policy(spec=SCAN), observation="scan").save(
        tmp_path / "scan.npz"
    )
    assert Surrogate.load(scan_sur, IMITATION7).spec == SCAN
    with np.load(scan_sur) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    header["features"]["observation"] = "contacts"
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "mixed.npz", **arrays)
    with pytest.raises(StudyMismatchError, match=r"observes 0 remembered contacts.*this mission's learner observes 3"):
        Surrogate.load(tmp_path / "mixed.npz", IMITATION7)


def test_a_surrogate_flies_the_batch_simulator_and_the_expert_annotates_it():
    sur = Surrogate.for_mission(IMITATION7, _steering_policy())
    X = np.random.default_rng(3).random((12, IMITATION7.dim))
    mine = sim.uuv.simulate(IMITATION7, X, surrogate=sur)
    expert = sim.uuv.simulate(IMITATION7, X)
    assert mine.valid.sum() >= 8 and not np.array_equal(mine.modes[mine.valid], expert.modes[mine.valid])
    result, trajs = annotated_runs(IMITATION7, X, SPEC, sur.policy)
    np.testing.assert_array_equal(result.scores, mine.scores)  # the shadow expert does not change the run
    for row in np.flatnonzero(result.valid):
        t = trajs[row]
        assert t.features.shape[0] == t.expert.shape[0] > 10 and t.features.shape[1] == SPEC.size
    # the expert's labels are not the policy's actions: the policy flies straight on, the expert steers
    t = trajs[int(np.flatnonzero(result.valid)[0])]
    assert np.abs(t.expert - sur.policy(t.features)).max() > 0.1


def test_the_learned_goal_decision_latches_and_the_expert_labels_the_learners_goal():
    """A learner that gives the waypoint up at once (its goal output is positive at any charge):
    from then on it sees no waypoint and flies home; the expert, asked in that state, heads
    home too (+1), and a second shadow that still pursues the waypoint says the learner
    should not have turned (-1) -- both sets of labels go with the features they describe."""
    from sim.uuv.imitation.driver import PolicyAutonomy

    quitter = _steering_policy(home_below=1.1)
    X = np.random.default_rng(4).random((16, IMITATION7.dim))
    X[:, 6] = 1.0  # full starting charge (40%): the expert never turns back for fuel early on
    result, trajs = annotated_runs(IMITATION7, X, SPEC, quitter)
    wp = slice(1, 4)
    for row in np.flatnonzero(result.valid)[:4]:
        t = trajs[row]
        shown = np.any(t.features[:, wp] != 0, axis=1)
        # learner's own states: no waypoint, the expert (in the learner's goal) heads home
        assert np.all(t.expert[~shown, 2] == 1.0) and (~shown).sum() > 10
        # the first step (not yet turned) and the pursuing shadow's labels, one a step after it,
        # with the waypoint in view: keep going
        assert shown.sum() == (~shown).sum() + 1 and np.mean(t.expert[shown, 2] == -1.0) > 0.9
        assert np.mean(t.expert[shown, 0] * t.features[shown, 1] + t.expert[shown, 1] * t.features[shown, 2]) > 0
    scen = make_scenarios(IMITATION7, X[:4])
    driver = PolicyAutonomy(scen, quitter, SPEC)
    world = World(scen, scan_beams=SPEC.beams)
    for step in range(3):  # the decision is taken on the waypoint's features, then they are gone
        obs = observation(world.telemetry(0.0), scen)
        driver.step(obs, IMITATION7.dt)
        assert np.all(driver.home) and np.all(np.any(driver.last_features[:, wp] != 0, axis=1) == (step == 0))
    # a policy that keeps going never latches
    keeper = PolicyAutonomy(scen, _steering_policy(home_below=-0.1), SPEC)
    keeper.step(obs, IMITATION7.dt)
    assert not keeper.home.any() and np.all(np.any(keeper.last_features[:, wp] != 0, axis=1))


def test_the_goal_threshold_moves_the_abort():
    """The hand-made policy's goal output is 20 (0.15 - charge): a threshold t turns it home below a
    charge of 0.15 - t / 20, here 20%, 12.5% and 10% at 13% charge."""
    X = np.random.default_rng(6).random((1, IMITATION7.dim))
    X[:, 6] = (0.13 - 0.05) / 0.35
    scen = make_scenarios(IMITATION7, X)
    obs = observation(World(scen, scan_beams=SPEC.beams).telemetry(0.0), scen)
    turned = []
    for threshold in (-1.0, 0.5, 1.0):
        driver = Surrogate.for_mission(IMITATION7, _steering_policy(0.15), goal_threshold=threshold).autonomy(scen)
        driver.step(obs, IMITATION7.dt)
        turned.append(bool(driver.home[0]))
    assert turned == [True, False, False]


def test_the_goal_threshold_is_calibrated_where_the_expert_turned():
    """Run A: the expert turns at step 10, the goal output rises -1, -0.9, ... and reaches 0 there;
    run B: the expert never turns, the output stays at -0.3.  Thresholds in [-0.3, 0) reproduce
    both (A first crosses within 5 steps before the turn, B never); -0.9 turns both too early,
    +0.9 never turns A."""
    from planner.plan.surrogate import calibrate_goal_threshold

    def run(goal, turn_at):
        F = np.zeros((len(goal), 4), np.float32)
        F[:, 0], F[:, 1:4] = goal, 0.5  # column 0 carries the goal output; a waypoint is pending
        A = np.full((len(goal), 3), -1.0, np.float32)
        if turn_at is not None:
            A[turn_at, 2] = 1.0
            F = F[: turn_at + 1]
            A = A[: turn_at + 1]
        return Trajectory(F, A)

    class Reader:  # a policy whose goal output is feature 0
        def __call__(self, F, quiet=None):
            return np.column_stack([np.zeros(len(F)), np.zeros(len(F)), F[:, 0]])

    spec = dataclasses.replace(SPEC, beams=0)
    trajs = [run(-1.0 + 0.1 * np.arange(30), 10), run(np.full(30, -0.3), None)]
    grid = np.round(np.arange(-0.9, 0.91, 0.1), 1)
    threshold, share = calibrate_goal_threshold(Reader(), spec, trajs, grid)
    assert share[0] == 0.0 and share[-1] == 0.5 and max(share) == 1.0
    assert -0.3 <= threshold < 0.0 and share[int(np.argmin(np.abs(grid - threshold)))] == 1.0


def test_on_the_bus_the_surrogate_flies_while_the_expert_commands_are_logged(tmp_path):
    """Figure 6.3: the surrogate is the active source; the expert still decides every step, recorded."""
    from bridge.logger import read_log
    from planner.fly.sil.loop import run_sil

    sur = Surrogate.for_mission(IMITATION7, _steering_policy())
    X = np.random.default_rng(3).random((12, IMITATION7.dim))
    batch = sim.uuv.simulate(IMITATION7, X, surrogate=sur)
    expert = sim.uuv.simulate(IMITATION7, X)
    row = int(np.flatnonzero(batch.valid & (batch.modes != expert.modes))[0])
    log = tmp_path / "bus.mcap"
    result = run_sil(IMITATION7, X[row], surrogate=sur, log_path=log)
    # the vehicle flew the surrogate: its scores are the batch surrogate's, bit for bit (the scan
    # crossed MAVLink as five OBSTACLE_DISTANCE messages a step), not the expert's
    np.testing.assert_array_equal(result.scores, batch.scores[row])
    assert not np.array_equal(result.scores, expert.scores[row])
    commands: dict[str, list] = {}
    for topic, _, _ in read_log(log):
        if "/command/" in topic:
            commands.setdefault(topic.rsplit("/", 1)[1], []).append(topic)
    assert set(commands) == {"autonomy", "surrogate"}
    # the expert answered (nearly) every step the surrogate did: its commands are recorded, not obeyed
    assert len(commands["autonomy"]) >= 0.95 * len(commands["surrogate"]) > 10


def test_the_bus_refuses_a_surrogate_of_another_mission():
    from planner.fly.sil.loop import run_sil

    other = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    sur = Surrogate.for_mission(IMITATION7, _steering_policy())
    with pytest.raises(ValueError, match="trained for mission 'imitation7'"):
        run_sil(other, np.full(other.dim, 0.5), surrogate=sur)


def test_agreement_figures_on_labels_with_known_answers():
    from rapt.agreement import agreement, path_error

    X = np.random.default_rng(0).random((2000, 2))
    truth = (X[:, 0] > 0.5).astype(int) + 2 * (X[:, 1] > 0.7)
    same = agreement(X, truth, truth)
    assert same.mode_accuracy == 1.0 and same.boundary_accuracy == same.straddled == 1.0
    assert same.distance_error == 0.0
    assert np.trace(same.confusion) == 2000 and same.mismatches == 0
    shifted = (X[:, 0] > 0.51).astype(int) + 2 * (X[:, 1] > 0.7)  # the x boundary moved by 0.01
    a = agreement(X, truth, shifted)
    assert a.mode_accuracy == pytest.approx(1 - np.mean((X[:, 0] > 0.5) & (X[:, 0] <= 0.51)))
    assert a.confusion[1, 0] + a.confusion[3, 2] == a.mismatches > 0 and a.confusion[0, 1] == 0
    # a shift of half a pair's length: a quarter of the surrogate's pairs no longer straddle the
    # true boundary, but nine in ten still lie in one of its regions; a shift of 1.5 pair
    # lengths moves the regions too
    assert 0.6 < a.straddled < a.boundary_accuracy and a.boundary_accuracy >= 0.85
    assert agreement(X, truth, (X[:, 0] > 0.53).astype(int) + 2 * (X[:, 1] > 0.7)).boundary_accuracy < 0.6
    assert 0.0 < a.distance_error < 0.01
    assert a.mismatches_near_boundary == 1.0  # the mistakes lie in the band next to the boundary
    noise = np.random.default_rng(1).integers(0, 4, 2000)
    assert agreement(X, truth, noise).straddled < 0.9 and agreement(X, truth, noise).mode_accuracy < 0.4
    p = [np.array([[0, 0], [1, 0], [2, 0]], float)]
    q = [np.array([[0, 0], [1, 1]], float)]
    assert path_error(p, q) == pytest.approx((0 + 1 + np.hypot(1, 1)) / 3)


def test_a_decision_does_not_depend_on_the_batch_it_is_in():
    rng = np.random.default_rng(0)
    policy = MLPPolicy(
        [
            rng.normal(0, 0.3, (SCAN.size, 150)).astype(np.float32),
            rng.normal(0, 0.3, (150, 50)).astype(np.float32),
            rng.normal(0, 0.3, (50, 2)).astype(np.float32),
        ],
        [
            rng.normal(size=150).astype(np.float32),
            rng.normal(size=50).astype(np.float32),
            rng.normal(size=2).astype(np.float32),
        ],
    )
    F = rng.uniform(-1, 1, (300, SCAN.size)).astype(np.float32)
    F[::3, SCAN.sonar] = 1.0  # open water on a third of the rows
    full = policy(F, quiet=SCAN.quiet)
    for rows in (np.arange(1), np.arange(5, 6), np.arange(17, 120), rng.permutation(300)[:77]):
        part = policy(F[rows], quiet=SCAN.quiet)
        np.testing.assert_array_equal(part, full[rows])
    np.testing.assert_allclose(policy(F), full, rtol=1e-5, atol=1e-6)


def test_the_scan_matches_a_brute_force_ray_cast():
    from sim.uuv.geometry import triangle_vertices

    rng = np.random.default_rng(4)
    n = 60
    x, y, h = rng.uniform(-120, 120, n), rng.uniform(-120, 120, n), rng.uniform(-np.pi, np.pi, n)
    tri = triangle_vertices(rng.uniform(-90, 90, (n, 2)), rng.uniform(-90, 90, (n, 2)), 80.0)
    bar = np.tile(np.array([[[-30.0, 30.0, 60.0, 80.0]]]), (n, 1, 1))
    got = scan(x, y, h, tri, bar, 100.0)
    x0, x1, y0, y1 = -30.0, 30.0, 60.0, 80.0
    rect = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    for i in range(n):
        polys = [tri[i, 0], tri[i, 1], rect]
        segs = [(p[k], p[(k + 1) % len(p)]) for p in polys for k in range(len(p))]
        for b in range(0, 360, 7):
            d = np.array([np.sin(h[i] + np.deg2rad(b)), np.cos(h[i] + np.deg2rad(b))])
            best = np.inf
            for a, c in segs:
                e = c - a
                den = d[0] * e[1] - d[1] * e[0]
                if abs(den) < 1e-12:
                    continue
                w = a - np.array([x[i], y[i]])
                t, s = (w[0] * e[1] - w[1] * e[0]) / den, (w[0] * d[1] - w[1] * d[0]) / den
                if t >= 0 and 0 <= s <= 1:
                    best = min(best, t)
            expect = np.round(best * 100) / 100 if best <= 100 else 100.01
            if got[i].max() == 0:  # inside an obstacle
                continue
            assert got[i, b] == pytest.approx(expect, abs=0.011), (i, b)


def test_the_exact_forward_pass_is_the_plain_network_and_saturates_without_warnings():
    from scipy.special import expit

    rng = np.random.default_rng(3)
    sizes = (SPEC.size, 150, 50, 3)
    for scale in (0.3, 600.0):  # 600: pre-activations past 710, where exp(-z) overflows
        W = [rng.normal(0, scale / np.sqrt(a), (a, b)).astype(np.float32) for a, b in zip(sizes, sizes[1:])]
        B = [rng.normal(0, scale, b).astype(np.float32) for b in sizes[1:]]
        F = rng.uniform(-1, 1, (200, SPEC.size)).astype(np.float32)
        F[::2, SPEC.sonar] = 1.0
        F[1::4, SPEC.sonar] = np.float32(1.0 - 2.0**-20)  # off "quiet", yet on the 2^-16 grid it is quiet
        h = np.round(F.astype(np.float64) * 2**16) / 2**16  # the plain network on the same input grid
        for k, (w, b) in enumerate(zip(W, B)):
            h = h @ w.astype(np.float64) + b
            if k < len(W) - 1:
                h = np.round(expit(h) * 2**16) / 2**16
        with np.errstate(over="raise", divide="raise", invalid="raise"):  # what numpy warns of by default
            got = MLPPolicy(W, B, "logistic")(F, quiet=SPEC.sonar)
        # weights on their exact grid move an output by far less than the 2^-16 activation grid
        np.testing.assert_allclose(got, h, rtol=0, atol=1e-4 * scale)
        nearly_quiet = F[1::4].copy()
        nearly_quiet[:, SPEC.sonar] = 1.0
        np.testing.assert_array_equal(got[1::4], MLPPolicy(W, B, "logistic")(nearly_quiet, quiet=SPEC.sonar))


def test_the_learner_remembers_a_contact_that_left_the_sonars_view_as_the_expert_does():
    """A contact seen ahead-starboard at t = 0 leaves the 120-degree field of view as the vehicle turns
    east (no longer detected): for 30 s the learner's contact slot still holds it, in the new body
    frame, and the expert still steers away from it; at t = 40 s both have forgotten it."""
    from sim.uuv.autonomy import Autonomy, Observation
    from sim.uuv.imitation.driver import PolicyAutonomy

    X = np.full((1, IMITATION7.dim), 0.5)
    scen = make_scenarios(IMITATION7, X)

    def obs(t, heading, seen):
        cx, cy = np.array([[10.0, 0.0, 0.0]]), np.array([[30.0, 0.0, 0.0]])
        detected = np.array([[seen, False, False]])
        one = np.zeros(1)
        return Observation(t, one.copy(), one.copy(), np.array([heading]), np.array([0.3]), cx, cy, one, detected)

    learner = PolicyAutonomy(scen, _steering_policy(), SPEC)
    expert, forgetful = Autonomy(scen), Autonomy(scen)
    learner.step(obs(0.0, 0.0, True), 2.0)
    expert.step(obs(0.0, 0.0, True), 2.0)
    slot = learner.last_features[0, SPEC.sonar]
    r = np.hypot(10.0, 30.0)
    np.testing.assert_allclose(slot[:3], [(100 - r) / 100, 30 / r, 10 / r], atol=1e-4)  # ahead, to starboard
    assert np.all(slot[3:] == 0)  # the other slots are empty
    # turned east, the contact is out of view: the learner still sees it, now to port
    turned = obs(2.0, np.pi / 2, False)
    learner.step(turned, 2.0)
    slot = learner.last_features[0, SPEC.sonar]
    np.testing.assert_allclose(slot[:3], [(100 - r) / 100, 10 / r, -30 / r], atol=1e-4)
    # the expert steers away from it too: its command differs from one that never saw the contact
    remembered, fresh = expert.step(turned, 2.0), forgetful.step(turned, 2.0)
    assert abs(float(remembered.heading[0] - fresh.heading[0])) > 0.05
    # the features are what the expert's memory holds: the same point, under the same rule
    assert expert.memory.x[0, 0] == learner.memory.x[0, 0] == 10.0
    late = obs(40.0, np.pi / 2, False)
    learner.step(late, 2.0)
    assert np.all(learner.last_features[0, SPEC.sonar] == 0)
    np.testing.assert_array_equal(expert.step(late, 2.0).heading, Autonomy(scen).step(late, 2.0).heading)
