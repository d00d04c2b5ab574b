"""Training where the boundaries are: the learner's search picks the expert's next scenarios and held-out pairs."""

from __future__ import annotations

import numpy as np

import sim.uuv
from planner.plan.surrogate_training import HeldOutPairs, directed_scenarios
from sim.uuv.imitation.surrogate import Surrogate
from tests.support.hand_policy import IMITATION7, SPEC, GreedyPolicy

BATTERY = 6  # start_battery's column of the unit cube


def test_directed_scenarios_straddle_the_learners_own_boundaries():
    """A learner that flies straight at its goal and turns home below 15 % charge: its search shows where its modes flip, and the
    expert is asked on both sides of those flips, not uniformly over the space."""
    policy = GreedyPolicy(home_below=0.15)
    X = directed_scenarios(IMITATION7, SPEC, policy, None, 20, np.random.default_rng(0), search_runs=300, seed=1)
    assert X.shape == (20, IMITATION7.dim)
    learner = sim.uuv.simulate(IMITATION7, X, surrogate=Surrogate.for_mission(IMITATION7, policy))
    ends = learner.modes.reshape(-1, 2)
    assert np.mean(ends[:, 0] != ends[:, 1]) >= 0.8  # consecutive rows are the two ends of a pair
    gaps = np.linalg.norm(X[0::2] - X[1::2], axis=1)
    assert np.median(gaps) < 0.5  # ... and the ends lie close together (two uniform draws: about 1.1 apart)
    # a rarer type is asked about as well as the commonest: more than one boundary type among the pairs
    assert len({tuple(sorted(e)) for e in ends.tolist() if e[0] != e[1]}) >= 2
    # the same seed gives the same scenarios
    again = directed_scenarios(IMITATION7, SPEC, policy, None, 20, np.random.default_rng(0), search_runs=300, seed=1)
    np.testing.assert_array_equal(X, again)


def test_directed_scenarios_ask_where_two_updates_disagree():
    keen, cautious = GreedyPolicy(home_below=0.10), GreedyPolicy(home_below=0.25)
    X = directed_scenarios(IMITATION7, SPEC, keen, cautious, 20, np.random.default_rng(0), search_runs=300, seed=2)
    a = sim.uuv.simulate(IMITATION7, X, surrogate=Surrogate.for_mission(IMITATION7, keen)).modes
    b = sim.uuv.simulate(IMITATION7, X, surrogate=Surrogate.for_mission(IMITATION7, cautious)).modes
    assert np.sum(a != b) >= 10  # half the asks where the two learners end in different modes


def test_held_out_pairs_score_an_update_on_the_experts_boundary_pairs_type_by_type():
    policy = GreedyPolicy(home_below=0.15)
    held = HeldOutPairs.around(IMITATION7, SPEC, policy, 16, seed=3)
    assert held.X.shape == (16, IMITATION7.dim) and len(held.trajectories) == 16
    assert held.pairs.shape == (8, 2) and np.all(held.expert.valid)  # every run is an end of a pair
    # the score, on pairs whose expert modes are known: the expert's fuel boundary (SS/TS) at two
    # obstacle layouts, and a pair it does not flip across
    u = np.full((6, IMITATION7.dim), 0.5)
    u[:, BATTERY] = [0.2, 0.5, 0.2, 0.5, 0.9, 0.95]
    u[2:4, 0] = 0.1
    expert = sim.uuv.simulate(IMITATION7, u, trajectories=True)
    e = expert.modes
    assert e[0] != e[1] and e[2] != e[3] and e[4] == e[5]
    pairs = np.arange(6).reshape(3, 2)
    held = HeldOutPairs(IMITATION7, "contacts", u, pairs, expert)
    assert held.boundary_pairs().tolist() == [[0, 1], [2, 3]]
    recall, mode, path = held(policy)
    mine = sim.uuv.simulate(IMITATION7, u, surrogate=Surrogate.for_mission(IMITATION7, policy)).modes
    right = [(mine[i] == e[i]) & (mine[j] == e[j]) for i, j in ((0, 1), (2, 3))]
    assert recall == np.mean(right) and mode == np.mean(mine == e) and path < 0


def test_training_is_seeded_and_lists_the_expert_runs_it_spent():
    """Three updates (the third directed) and 10 held-out runs: the same seed gives the same surrogate and
    the same expert scenarios, every one of which the file lists."""
    from planner.plan.surrogate import train_surrogate

    options = dict(runs=30, runs_per_iteration=10, select_runs=10, epochs=3, seed=4)
    one, two = train_surrogate(IMITATION7, **options), train_surrogate(IMITATION7, **options)
    flown = np.asarray(one.training["expert_scenarios"])
    assert flown.shape == (40, IMITATION7.dim) and one.training["runs"] == 40
    np.testing.assert_array_equal(flown, two.training["expert_scenarios"])
    F = np.random.default_rng(0).uniform(-1, 1, (50, SPEC.size)).astype(np.float32)
    np.testing.assert_array_equal(one.policy(F), two.policy(F))
    assert one.training["directed"] == 0.5 and one.training["method"] == "qdagger(50)"
