"""Train a surrogate where the boundaries are: directed annotation runs and held-out expert pairs.

Uniformly drawn training scenarios fall where the learner is already right, and a
rare boundary (a collision) gets one or two runs in all.  So after the first updates:

* **the annotated runs go to the learner's boundaries** (:func:`directed_rollout`): the
  learner runs its own S-NDV search (cheap: it is the learner, not the expert, that
  flies), and the expert annotates both ends of its boundary pairs, every type in turn
  (the rarest first), and the scenarios where the last two updates disagree;
* **the held-out expert runs are boundary pairs** (:class:`HeldOutPairs`): pairs of the
  learner's candidates, flown by the expert.  Those across which the expert changes
  mode are the expert's own boundary pairs, and each update is judged on how many of
  them it reproduces with both ends right, type by type: the figure a boundary search
  needs, where mode accuracy is dominated by the interior of the commonest mode.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import rapt
import sim.uuv
from planner.plan.generate import ROOT_COLUMNS, MissionScores
from rapt.agreement import path_error
from rapt.imitation.policies import Policy
from rapt.imitation.queries import boundary_queries, pair_queries
from sim.uuv.imitation.features import FeatureSpec
from sim.uuv.imitation.rollouts import annotated_runs, draw_valid
from sim.uuv.imitation.surrogate import Surrogate
from sim.uuv.mission import Mission

__all__ = ["directed_rollout", "directed_scenarios", "learner_search", "HeldOutPairs", "DIRECTED_FROM", "SEARCH_RUNS"]

#: Iterations 0 (the expert flies) and 1 draw uniformly; from this one on, runs are directed.
DIRECTED_FROM = 2
#: Runs of the learner's own S-NDV search per directed update.
SEARCH_RUNS = 600


def learner_search(mission: Mission, policy: Policy, observation: str, runs: int, seed: int) -> tuple:
    """The learner's own S-NDV search of ``runs`` scenarios: (unit-cube states, modes) of the valid ones."""
    study = rapt.search(
        MissionScores(mission, Surrogate.for_mission(mission, policy, observation=observation)),
        mission.space,
        int(runs),
        method="s-ndv",
        batch_size=max(50, int(runs) // 6),
        seed=int(seed),
        output_types=("binary", "binary"),
        steer=ROOT_COLUMNS,  # mission and safety success, as generate's search
        n_initial=int(runs) // 3,
    )
    return study.U, sim.uuv.scoring.modes_from_scores(study.Y)


def directed_rollout(
    mission: Mission,
    spec: FeatureSpec,
    seed: int = 0,
    mixing: float = 0.0,
    search_runs: int = SEARCH_RUNS,
    start: int = DIRECTED_FROM,
    share: float = 1.0,
    record: list | None = None,
):
    """A ``rollout(policy, k, iteration)`` for :func:`rapt.imitation.dagger.imitate` whose runs, from
    iteration ``start``, are :func:`~rapt.imitation.queries.boundary_queries` of the learner's search
    (a ``share`` of them; the rest drawn uniformly, which keeps the interior of the modes in view).

    Before that, and whenever the learner's search shows no boundary, it draws valid scenarios
    uniformly, seeded by ``(seed, iteration)`` as :func:`~sim.uuv.imitation.rollouts.make_rollout`.
    ``record``, a list, gets each iteration's scenarios appended.
    """
    last: dict = {}

    def rollout(policy, k, iteration):
        rng = np.random.default_rng([int(seed), int(iteration)])
        X, aimed = None, int(round(share * k))
        if policy is not None and iteration >= start and aimed:
            X = directed_scenarios(
                mission, spec, policy, last.get("policy"), aimed, rng, search_runs, seed * 1000 + iteration
            )
        X = draw_valid(mission, k, rng) if X is None else np.vstack([X, draw_valid(mission, k - aimed, rng)])
        if record is not None:
            record.append(X)
        if policy is not None:
            last["policy"] = policy
        beta = float(mixing) ** int(iteration) if mixing > 0 else 0.0
        _, trajs = annotated_runs(mission, X, spec, policy, seed=seed + int(iteration), beta=beta)
        return trajs

    return rollout


def directed_scenarios(
    mission: Mission,
    spec: FeatureSpec,
    policy: Policy,
    previous: Policy | None,
    k: int,
    rng: np.random.Generator,
    search_runs: int = SEARCH_RUNS,
    seed: int = 0,
) -> np.ndarray | None:
    """``k`` scenarios at ``policy``'s boundary candidates and where ``previous`` labels them otherwise
    (:func:`~rapt.imitation.queries.boundary_queries` of the learner's own search); None when its
    search shows a single mode."""
    U, modes = learner_search(mission, policy, spec.observation, search_runs, seed)
    if np.unique(modes).size < 2 or U.shape[0] < k:
        return None
    before = None
    if previous is not None:  # the last update's labels of the same scenarios
        before = sim.uuv.simulate(
            mission, U, surrogate=Surrogate.for_mission(mission, previous, observation=spec.observation)
        ).modes
    return U[boundary_queries(U, modes, k, rng, before)]


@dataclass
class HeldOutPairs:
    """Held-out expert runs at pairs of a learner's boundary candidates; call it with a policy to score it.

    ``pairs`` (P, 2) index ``X``; ``expert`` holds the expert's runs of ``X`` (with trajectories:
    they calibrate the goal threshold too).
    """

    mission: Mission
    observation: str
    X: np.ndarray
    pairs: np.ndarray
    expert: sim.uuv.Result
    trajectories: list = field(default_factory=list)

    @classmethod
    def around(cls, mission: Mission, spec: FeatureSpec, policy: Policy, runs: int, seed: int) -> HeldOutPairs:
        """``runs`` expert runs: both ends of pairs of ``policy``'s boundary candidates (its own search),
        topped up with uniform draws when it shows too few."""
        U, modes = learner_search(mission, policy, spec.observation, SEARCH_RUNS, seed)
        pairs = pair_queries(U, modes, runs // 2) if np.unique(modes).size > 1 else np.zeros((0, 2), np.int64)
        X = U[pairs.reshape(-1)]
        extra = runs - X.shape[0]
        if extra > 0:
            X = np.vstack([X, draw_valid(mission, extra, np.random.default_rng([int(seed), 0x686F6C64]))])
        return cls.flown(mission, spec, X, np.arange(pairs.size).reshape(-1, 2))

    @classmethod
    def uniform(cls, mission: Mission, spec: FeatureSpec, runs: int, seed: int) -> HeldOutPairs:
        """``runs`` expert runs on uniformly drawn valid scenarios, no pairs among them (``--uniform``)."""
        X = draw_valid(mission, runs, np.random.default_rng([int(seed), 0x73656C]))
        return cls.flown(mission, spec, X, np.zeros((0, 2), np.int64))

    @classmethod
    def flown(cls, mission: Mission, spec: FeatureSpec, X: np.ndarray, pairs: np.ndarray) -> HeldOutPairs:
        """The expert's runs of ``X``: its annotated states (for the goal threshold) and its tracks."""
        _, trajectories = annotated_runs(mission, X, spec)
        expert = sim.uuv.simulate(mission, X, trajectories=True)
        return cls(mission, spec.observation, X, pairs, expert, trajectories)

    def boundary_pairs(self) -> np.ndarray:
        """The held-out pairs across which the expert changes mode (its boundary pairs)."""
        m = self.expert.modes
        return self.pairs[m[self.pairs[:, 0]] != m[self.pairs[:, 1]]] if self.pairs.size else self.pairs

    def __call__(self, policy: Policy) -> tuple[float, float, float]:
        """(mean over the expert's boundary types of the share of its held-out pairs with both ends right,
        mode accuracy on every held-out run, minus the mean path error): higher is better."""
        sur = Surrogate.for_mission(self.mission, policy, observation=self.observation)
        mine = sim.uuv.simulate(self.mission, self.X, surrogate=sur, trajectories=True)
        e, s = self.expert.modes, mine.modes
        ok = self.expert.valid & mine.valid
        mode = float(np.mean(s[ok] == e[ok])) if ok.any() else 0.0
        bp = self.boundary_pairs()
        recall = 0.0
        if bp.size:
            right = (s[bp[:, 0]] == e[bp[:, 0]]) & (s[bp[:, 1]] == e[bp[:, 1]])
            kinds = np.sort(np.column_stack([e[bp[:, 0]], e[bp[:, 1]]]), axis=1)
            _, which = np.unique(kinds, axis=0, return_inverse=True)
            recall = float(np.mean([np.mean(right[which.reshape(-1) == t]) for t in np.unique(which)]))
        rows = np.flatnonzero(ok).tolist()
        error = path_error([_track(self.expert, i) for i in rows], [_track(mine, i) for i in rows])
        return recall, mode, -error if np.isfinite(error) else 0.0


def _track(result: sim.uuv.Result, row: int) -> np.ndarray:
    """A run's (x, y) positions (a valid row simulated with trajectories has them)."""
    path = result.trajectory(row)
    assert path is not None, "simulated with trajectories=True"
    return path[:, 1:3]
