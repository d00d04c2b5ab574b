"""The imitation learners on tiny problems: behavioural cloning, DAgger, Q-DAgger (Algorithm 9), decision heads."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.errors import InputError
from rapt.imitation.dagger import Trajectory, imitate
from rapt.imitation.policies import HeadsPolicy, MLPPolicy, policy_from_arrays

#: A network and training small enough for the tiny problems: 4 runs an update, one hidden layer of 16.
SMALL_NET = dict(runs_per_iteration=4, hidden=(16,), epochs=60, learning_rate=0.01, batch_size=64, seed=1)


# -- the learners on a tiny problem ------------------------------------------------------------------
def _point_mass_rollout(log):
    """A 1-D vehicle: the expert steers to a goal at constant gain, saturating at 1; the world is f(x, goal)."""

    def rollout(policy, k, iteration):
        rng = np.random.default_rng(iteration)
        out = []
        for _ in range(k):
            x, goal = rng.uniform(-1, 1), rng.uniform(-1, 1)
            F, A = [], []
            for _ in range(25):
                f = np.array([x, goal], np.float32)
                expert = np.clip(2.0 * (goal - x), -1, 1)
                act = expert if policy is None else float(policy(f[None, :])[0, 0])
                F.append(f)
                A.append([expert])
                x = x + 0.2 * act
            out.append(Trajectory(np.array(F), np.array(A, np.float32)))
            log.append(abs(x - goal))
        return out

    return rollout


@pytest.mark.parametrize("method", ["supervised", "dagger", "qdagger", "qdagger-new"])
def test_each_learner_learns_a_tiny_expert(method):
    log = []
    result = imitate(
        _point_mass_rollout(log),
        method=method,
        quantile=0.5,
        iterations=6,
        **SMALL_NET,
    )
    assert [r.runs for r in result.history] == [4, 8, 12, 16, 20, 24, 28]
    sizes = [r.samples for r in result.history]
    grown = np.diff(sizes)
    if method == "qdagger":  # Algorithm 9: the new 100 states plus the worse half of the aggregate so far
        assert sizes[0] == 100 and all(100 + s // 2 <= t <= 101 + s // 2 for s, t in zip(sizes, sizes[1:]))
        assert max(sizes) < 200  # bounded by |D_i| / (1 - quantile)
    elif method == "qdagger-new":
        assert np.all(grown <= 50) and np.all(grown >= 45)  # half of each new set of 100 states
    else:
        assert np.all(grown == 100)
    # the learned policy flies the point mass to its goal from states it never saw
    test = []
    _point_mass_rollout(test)(result.policy, 20, 1000)
    assert np.median(test) < 0.05, (method, np.median(test))
    assert result.history[-1].loss < 0.01


def test_algorithm_9_re_mines_the_aggregate_for_what_the_policy_still_gets_wrong():
    """Iteration 0's expert runs hold one hard state (a label the network cannot fit among its
    neighbours); after it the rollouts are easy.  Algorithm 9 keeps re-selecting the hard state from
    the aggregate while the easy old states drop out: it is still there after five updates, in a set
    bounded near |D_i| / (1 - quantile); trimming only the new sets keeps every old state."""

    def rollout(policy, k, iteration):
        rng = np.random.default_rng(iteration)
        F = rng.uniform(-1, 1, (k * 20, 1)).astype(np.float32)
        A = np.zeros((k * 20, 1), np.float32)
        if iteration == 0:
            F[0], A[0] = 0.0, 1.0  # the hard state
        return [Trajectory(F[r * 20 : (r + 1) * 20], A[r * 20 : (r + 1) * 20]) for r in range(k)]

    sizes = {}
    for method in ("qdagger", "qdagger-new"):
        result = imitate(
            rollout,
            method=method,
            iterations=5,
            runs_per_iteration=2,
            hidden=(4,),
            epochs=5,
            seed=0,
        )
        F, A = result.aggregate
        assert np.sum((F[:, 0] == 0.0) & (A[:, 0] == 1.0)) == 1  # the hard state survived every re-mining
        sizes[method] = F.shape[0]
        assert result.method == method and result.quantile == 0.5
    assert sizes["qdagger"] < 80 and sizes["qdagger-new"] == 40 + 5 * 20


@pytest.mark.parametrize("method", ["supervised", "dagger", "qdagger"])
def test_only_behavioural_cloning_leaves_every_run_to_the_expert(method):
    """Supervised learning (Table 6.3's baseline) trains on the expert's own runs: the rollout is never
    handed a policy, and every state is kept.  The DAgger family lets the learner fly from update 1."""
    fliers = []
    inner = _point_mass_rollout([])

    def rollout(policy, k, iteration):
        fliers.append(policy)
        return inner(policy, k, iteration)

    result = imitate(rollout, method=method, iterations=3, runs_per_iteration=2, hidden=(8,), epochs=5, seed=0)
    assert fliers[0] is None
    if method == "supervised":
        assert all(p is None for p in fliers) and [r.samples for r in result.history] == [50, 100, 150, 200]
        assert result.quantile is None
    else:
        assert all(p is not None for p in fliers[1:])


def test_the_best_policy_on_validation_is_returned():
    """DAgger returns the best policy of the sequence on held-out runs, not the last (ties: the later)."""
    scores = iter([0.1, 0.5, 0.3, 0.5, 0.2])
    seen, weights = [], []
    result = imitate(
        _point_mass_rollout([]),
        method="dagger",
        iterations=4,
        runs_per_iteration=2,
        hidden=(8,),
        epochs=5,
        select=lambda p: (seen.append(p), weights.append([w.copy() for w in p.weights]), next(scores))[2],
    )
    assert result.chosen == 3 and result.policy is seen[3] and result.history[3].extra["selection"] == 0.5
    # the kept policy's weights are those it was scored with: later updates do not train it on
    for kept, scored in zip(result.policy.weights, weights[3]):
        np.testing.assert_array_equal(kept, scored)
    assert any(not np.array_equal(a, b) for a, b in zip(weights[3], weights[4]))
    last = imitate(_point_mass_rollout([]), method="dagger", iterations=2, runs_per_iteration=2, hidden=(8,), epochs=5)
    assert last.chosen == 2


def _latched_switch_rollout(threshold: float):
    """Runs whose charge-like feature x falls 0.02 a step from a random start; the expert switches
    (+1) at the first x <= ``threshold`` and latches: the run then shows "no waypoint pending"
    (feature 1 is 0), so among pending states the +1 label appears once per run."""

    def rollout(policy, k, iteration):
        rng = np.random.default_rng([7, iteration])
        out = []
        for _ in range(k):
            F, A, home = [], [], False
            for x in np.arange(rng.uniform(-0.2, 1.0), -1.0, -0.02):
                turn = home or x <= threshold
                F.append([x, 0.0 if home else 1.0])
                A.append([0.5 * x, 1.0 if turn else -1.0])
                home = turn
            out.append(Trajectory(np.array(F, np.float32), np.array(A, np.float32)))
        return out

    return rollout


@pytest.mark.parametrize("seed", [0, 1])
def test_a_decision_head_places_a_switch_sharply_where_regression_ramps(seed):
    """The same runs, the same network shape and epochs: regressed on +-1 the latched switch is a
    ramp half the input range wide, crossing zero well short of the expert's threshold; learned as
    a decision (classifier, switch-weighted) it is a step a quarter as wide, nearer the threshold."""
    threshold = 0.3
    grid = np.column_stack([np.linspace(-1, 1, 2001), np.ones(2001)]).astype(np.float32)  # pending states
    found = {}
    for decisions in ((), (1,)):
        result = imitate(
            _latched_switch_rollout(threshold),
            method="supervised",
            iterations=5,
            runs_per_iteration=4,
            hidden=(16, 8),
            epochs=60,
            seed=seed,
            decisions=decisions,
        )
        goal = result.policy(grid)[:, 1]
        undecided = grid[(goal > -0.8) & (goal < 0.8), 0]
        found[decisions] = (grid[goal > 0, 0].max(), undecided.max() - undecided.min())
    (cross_r, ramp_r), (cross_d, ramp_d) = found[()], found[(1,)]
    assert ramp_r > 0.45 and ramp_d < 0.3 and ramp_d < ramp_r / 2
    assert abs(cross_d - threshold) < abs(cross_r - threshold) and abs(cross_d - threshold) < 0.1
    assert result.policy.heads[1][2].output == "decision"  # saved and flown as 2 p - 1


def test_decisions_are_checked():
    rollout = _latched_switch_rollout(0.3)
    with pytest.raises(InputError, match=r"decisions: expected distinct action columns 0\.\.1"):
        imitate(rollout, iterations=0, decisions=[2])
    with pytest.raises(InputError, match="a decision column needs a head of its own"):
        imitate(rollout, iterations=0, decisions=[1], heads=[(None, [0, 1])])
    with pytest.raises(InputError, match="switch_weight: expected a weight >= 1"):
        imitate(rollout, iterations=0, decisions=[1], switch_weight=0.5)


def _net(rng, n_in, n_out, hidden=(12, 6)):
    sizes = [n_in, *hidden, n_out]
    return MLPPolicy(
        [rng.normal(0, 0.5, (a, b)).astype(np.float32) for a, b in zip(sizes, sizes[1:])],
        [rng.normal(0, 0.5, b).astype(np.float32) for b in sizes[1:]],
    )


def test_a_head_reads_only_its_columns_and_heads_round_trip():
    rng = np.random.default_rng(3)
    policy = HeadsPolicy(
        10, [(np.arange(10), np.array([0, 1]), _net(rng, 10, 2)), (np.array([0, 1, 9]), np.array([2]), _net(rng, 3, 1))]
    )
    F = rng.uniform(-1, 1, (40, 10)).astype(np.float32)
    G = F.copy()
    G[:, 2:9] = rng.uniform(-1, 1, (40, 7))
    a, b = policy(F), policy(G)
    assert a.shape == (40, 3) and policy.n_outputs == 3
    assert np.abs(a[:, :2] - b[:, :2]).max() > 1e-3  # the first head reads columns 2-8 ...
    np.testing.assert_array_equal(a[:, 2], b[:, 2])  # ... the second never does
    F[::2, 2:9] = 1.0  # the quiet shortcut of the head that reads the block gives the same numbers
    np.testing.assert_array_equal(policy(F, quiet=slice(2, 9)), policy(F))
    back = policy_from_arrays(policy.to_arrays())
    assert isinstance(back, HeadsPolicy)
    np.testing.assert_array_equal(back(F), policy(F))


def test_heads_learn_their_parts_and_a_decision_ignores_what_it_cannot_see():
    """The point mass with a second action, the sign of the goal, learned by a head reading the goal
    alone: a third feature that tracks the decision in training (a spurious cue) cannot move it."""
    inner = _point_mass_rollout([])

    def rollout(policy, k, iteration):
        wrapped = None if policy is None else (lambda f: policy(np.column_stack([f, np.sign(f[:, 1:2])]))[:, :1])
        out = []
        for t in inner(wrapped, k, iteration):
            cue = np.sign(t.features[:, 1:2])  # in training the cue equals the decision
            out.append(Trajectory(np.column_stack([t.features, cue]), np.column_stack([t.expert, cue])))
        return out

    result = imitate(
        rollout,
        method="dagger",
        iterations=3,
        **SMALL_NET,
        heads=((None, [0]), ([1], [1])),
    )
    policy = result.policy
    assert isinstance(policy, HeadsPolicy) and policy.n_outputs == 2
    F = np.array([[0.0, 0.6, 1.0], [0.0, 0.6, -1.0], [0.0, -0.6, -1.0], [0.0, -0.6, 1.0]], np.float32)
    decision = policy(F)[:, 1]
    assert decision[0] == decision[1] > 0.5 and decision[2] == decision[3] < -0.5
    with pytest.raises(ValueError, match="heads: output columns must cover"):
        imitate(rollout, method="supervised", iterations=0, runs_per_iteration=2, heads=((None, [0]),))
    with pytest.raises(ValueError, match=r"heads\[1\]: input columns"):
        imitate(rollout, method="supervised", iterations=0, runs_per_iteration=2, heads=((None, [0]), ([7], [1])))


def test_bad_learner_settings_are_named():
    with pytest.raises(ValueError, match="method"):
        imitate(lambda *a: [], method="dagger2")
    with pytest.raises(ValueError, match="quantile"):
        imitate(lambda *a: [], method="qdagger", quantile=1.5)
