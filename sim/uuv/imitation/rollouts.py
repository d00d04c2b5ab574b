"""Annotated runs for imitation learning: who flies, and what the expert would have done.

With no policy the expert flies (behavioural cloning data); with a policy the policy
flies and the expert rides along in the shadow, deciding on the very same reports at
every step — the DAgger annotation, and what the bus does when a surrogate commands the
vehicle while the expert's commands are recorded (Figure 6.3).
"""

from __future__ import annotations

import numpy as np

from rapt.errors import InputError
from rapt.imitation.dagger import Trajectory
from rapt.imitation.policies import MLPPolicy
from sim.uuv.autonomy import Autonomy, Command
from sim.uuv.contact_memory import ContactMemory
from sim.uuv.imitation.driver import PolicyAutonomy
from sim.uuv.imitation.features import (
    FeatureSpec,
    advance_waypoints,
    expert_action,
    features,
    obstacle_view,
    predicted_current,
    waypoint_target,
)
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import modes_from_scores
from sim.uuv.simulate import Result, run_scenarios
from sim.uuv.world import scenario_generators

__all__ = ["annotated_runs", "make_rollout", "draw_valid", "MixedDriver"]


class MixedDriver(PolicyAutonomy):
    """The policy flies, the expert decides in the shadow; with probability ``beta`` a step obeys the expert.

    ``beta`` is DAgger's mixing weight (Ross et al. 2011: pi_i = beta pi* + (1 - beta) pi_hat):
    early iterations stay near the expert's own states while the policy is still poor.

    The expert is asked what it would do in the learner's state, and its goal (heading home
    or not) is part of that state: before each step the shadow expert takes the learner's
    goal, then decides — its command, and whether it turns home now, label the learner's
    features (:attr:`labels`).  A second shadow, always still pursuing the waypoint, labels
    the states of a learner that has turned home with what the expert would do there with
    the waypoint pending: without it a learner that turned too early would be told so once,
    at the turn, while one that turned too late hears it every step until it turns.

    The annotating experts never give a goal up for lack of progress: that clock would time
    the learner's wobbles, which no feature shows, and turn its labels home mid-leg (the
    expert's own runs seldom abort a waypoint so on the chapter 6 mission).
    """

    def __init__(self, scen, policy, spec: FeatureSpec, beta: float = 0.0, rng: np.random.Generator | None = None):
        super().__init__(scen, policy, spec)
        self.expert, self.pursuer = Autonomy(scen), Autonomy(scen)
        self.expert.stuck_s = self.pursuer.stuck_s = np.inf
        self.beta, self.rng = float(beta), rng if rng is not None else np.random.default_rng(0)
        self.labels: tuple[np.ndarray, ...] | None = None

    def step(self, obs, dt, active=None):
        mine = super().step(obs, dt, active)
        self.expert.returning[:] = self.was_home
        theirs = self.expert.step(obs, dt, active)
        self.pursuer.returning[:] = False
        other = self.pursuer.step(obs, dt, active)
        F, rows = self.last_features, np.arange(obs.x.shape[0])
        heading, speed, home = theirs.heading, theirs.speed, self.expert.returning.copy()
        wx, wy, pending = self.last_target
        extra = np.flatnonzero(self.was_home & pending)  # turned home with the waypoint still to reach
        if extra.size:
            G = features(
                self.spec,
                self.mission,
                obs.t,
                obs.x[extra],
                obs.y[extra],
                obs.heading[extra],
                obs.battery[extra],
                self.last_view[extra],
                (wx[extra], wy[extra], pending[extra]),
                (self.last_tide[0][extra], self.last_tide[1][extra]),
            )
            F, rows = np.concatenate([F, G]), np.concatenate([rows, extra])
            heading = np.concatenate([heading, other.heading[extra]])
            speed = np.concatenate([speed, other.speed[extra]])
            home = np.concatenate([home, self.pursuer.returning[extra]])
        self.labels = (F, rows, heading, speed, home)
        if self.beta <= 0.0:
            return mine
        obey = self.rng.random(mine.heading.shape[0]) < self.beta
        return Command(
            np.where(obey, theirs.heading, mine.heading),
            np.where(obey, theirs.speed, mine.speed),
            np.where(obey, theirs.surface, mine.surface),
        )


def annotated_runs(
    mission: Mission,
    X: np.ndarray,
    spec: FeatureSpec,
    policy: MLPPolicy | None = None,
    seed: int = 0,
    stochastic: bool = False,
    beta: float = 0.0,
) -> tuple[Result, list[Trajectory]]:
    """Fly the valid scenarios ``X`` and return their scores and per-run (features, expert actions).

    With a ``policy`` it flies (obeying the expert on a ``beta`` share of steps, seeded by
    ``seed``) and the expert's shadow commands are the labels; without, the expert flies.
    """
    scen = make_scenarios(mission, X)
    rows = np.flatnonzero(scen.valid)
    names = metric_names(mission)
    scores = np.full((scen.n, len(names)), np.nan)
    trajs = [
        Trajectory(np.zeros((0, spec.size), np.float32), np.zeros((0, spec.actions), np.float32)) for _ in range(scen.n)
    ]
    if rows.size == 0:
        return Result(
            scores,
            modes_from_scores(scores),
            scen.valid.copy(),
            list(scen.invalid_reason),
            names,
            metric_types(mission),
        ), trajs
    sub = scen.select(rows)
    nxt = np.zeros(sub.n, dtype=np.int64)
    got_F: list[np.ndarray] = []
    got_A: list[np.ndarray] = []
    got_r: list[np.ndarray] = []

    expert_home = np.zeros(sub.n, dtype=bool)  # the flying expert's return latch before the step
    memory = ContactMemory(spec.memory_s)  # what the flying expert remembers, kept as a learner would

    def on_step(obs, cmd, active, driver):
        # Each state is recorded with the goal it was decided under, labelled with the
        # expert's command and whether it heads home after deciding (sim.uuv.imitation.features).
        nonlocal nxt
        if policy is not None:
            F, who, heading, speed, home = driver.labels
        else:
            nxt = advance_waypoints(mission, nxt, obs.x, obs.y)
            wx, wy, pending = waypoint_target(mission, nxt)
            view = obstacle_view(spec, memory, obs)
            target = (wx, wy, pending & ~expert_home)
            tide = predicted_current(mission, sub, obs)
            F = features(spec, mission, obs.t, obs.x, obs.y, obs.heading, obs.battery, view, target, tide)
            who, heading, speed, home = np.arange(sub.n), cmd.heading, cmd.speed, driver.returning.copy()
            expert_home[:] = home
        keep = np.flatnonzero(active[who])
        who = who[keep]
        got_F.append(F[keep])
        got_A.append(expert_action(spec, obs.heading[who], heading[keep], speed[keep], home[keep]))
        got_r.append(who)

    rngs = scenario_generators(np.asarray(X, dtype=float)[rows], seed) if stochastic else None
    mixing = np.random.default_rng([int(seed), 0x6D6978])
    driver = (lambda s: MixedDriver(s, policy, spec, beta, mixing)) if policy is not None else None
    out, _ = run_scenarios(sub, rngs, False, None, driver=driver, scan_beams=spec.beams, on_step=on_step)
    scores[rows] = out
    F, A, r = np.concatenate(got_F), np.concatenate(got_A), np.concatenate(got_r)
    order = np.argsort(r, kind="stable")
    F, A, r = F[order], A[order], r[order]
    cuts = np.searchsorted(r, np.arange(sub.n + 1))
    for k, row in enumerate(rows.tolist()):
        trajs[row] = Trajectory(F[cuts[k] : cuts[k + 1]], A[cuts[k] : cuts[k + 1]])
    return Result(
        scores, modes_from_scores(scores), scen.valid.copy(), list(scen.invalid_reason), names, metric_types(mission)
    ), trajs


def draw_valid(mission: Mission, k: int, rng: np.random.Generator) -> np.ndarray:
    """``k`` uniformly random valid scenarios of ``mission`` (unit-cube rows)."""
    out = np.empty((0, mission.dim))
    for _ in range(100):
        X = rng.random((max(2 * k, 8), mission.dim))
        out = np.vstack([out, X[make_scenarios(mission, X).valid]])
        if out.shape[0] >= k:
            return out[:k]
    raise InputError(f"mission: fewer than {k} valid scenarios in {100 * max(2 * k, 8)} random draws")


def make_rollout(
    mission: Mission,
    spec: FeatureSpec,
    seed: int = 0,
    stochastic: bool = False,
    mixing: float = 0.0,
    record: list | None = None,
):
    """A ``rollout(policy, k, iteration)`` for :func:`rapt.imitation.dagger.imitate` on random valid scenarios.

    Iteration ``i`` draws its scenarios from a generator seeded by ``(seed, i)``, so every
    learner sees the same scenarios at the same iteration.  ``mixing`` p makes iteration i obey the
    expert on a share p**i of its steps (DAgger's decaying beta; 0: Algorithm 9 as written).
    ``record``, a list, gets each iteration's scenarios appended.
    """

    def rollout(policy, k, iteration):
        X = draw_valid(mission, k, np.random.default_rng([int(seed), int(iteration)]))
        if record is not None:
            record.append(X)
        beta = float(mixing) ** int(iteration) if mixing > 0 else 0.0
        _, trajs = annotated_runs(
            mission, X, spec, policy, seed=seed + int(iteration), stochastic=stochastic, beta=beta
        )
        return trajs

    return rollout
