"""Run a batch of scenarios: world, sensors, autonomy and scorer stepped together with numpy.

Every scenario in the batch advances in lockstep by the mission's ``dt``; runs that end
(recovered, collided, out of the area, out of battery, out of time) are frozen and the
loop stops when none is left.  The autonomy and the scorer are the same objects the
software-in-the-loop path drives one vehicle at a time, so a scenario scores the same
alone as inside a batch (each scenario's random stream is its own).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sim.autonomy import Autonomy, Observation
from sim.environment import tidal_current
from sim.geometry import rect_signed_distance
from sim.metrics import metric_names, metric_types
from sim.mission import Mission
from sim.navigation import Navigation
from sim.scenario import Scenarios, make_scenarios
from sim.scoring import MODE_NAMES, Scorer, modes_from_scores
from sim.sonar import sense
from sim.vehicle import VehicleState, step_vehicle

__all__ = ["Result", "simulate", "run_scenarios", "TRAJECTORY_FIELDS"]

#: Per-step columns of a recorded trajectory.
TRAJECTORY_FIELDS = ("t", "x", "y", "heading", "speed", "battery", "surfaced", "goal")


@dataclass
class Result:
    """Scores of a batch: ``scores`` (N, m) in ``names`` order, NaN rows where ``valid`` is False.

    ``modes`` holds 0..3 for TF, SS, MS, TS (-1 when invalid); ``trajectories`` (when
    asked) is a list of (steps, len(TRAJECTORY_FIELDS)) arrays, None for invalid rows.
    """

    scores: np.ndarray
    modes: np.ndarray
    valid: np.ndarray
    invalid_reason: list[str]
    names: list[str]
    output_types: list[str]
    trajectories: list[np.ndarray | None] | None = None
    mode_names: tuple[str, ...] = field(default=MODE_NAMES)

    def column(self, name: str) -> np.ndarray:
        return self.scores[:, self.names.index(name)]


def simulate(mission: Mission, X: np.ndarray, seed: int = 0, stochastic: bool = False,
             trajectories: bool = False) -> Result:
    """Simulate unit-cube scenarios ``X`` (N, mission.dim) of ``mission``.

    ``stochastic`` switches on navigation drift and current perturbations, seeded per
    scenario from ``seed`` and the row's own values, so a row gives the same run alone or
    in any batch.
    """
    scen = make_scenarios(mission, X)
    names, types = metric_names(mission), metric_types(mission)
    scores = np.full((scen.n, len(names)), np.nan)
    trajs: list[np.ndarray | None] | None = [None] * scen.n if trajectories else None
    rows = np.flatnonzero(scen.valid)
    if rows.size:
        sub = scen.select(rows)
        rngs = _row_generators(np.asarray(X, dtype=float)[rows], seed) if stochastic else None
        got, tr = run_scenarios(sub, rngs, trajectories)
        scores[rows] = got
        if trajectories:
            for r, t in zip(rows.tolist(), tr):
                trajs[r] = t
    return Result(scores, modes_from_scores(scores), scen.valid.copy(), list(scen.invalid_reason), names, types,
                  trajs)


def _row_generators(X: np.ndarray, seed: int) -> list[np.random.Generator]:
    """One generator per scenario, keyed by the seed and the scenario's bytes."""
    out = []
    for row in X:
        words = np.frombuffer(np.ascontiguousarray(row).tobytes(), dtype=np.uint32)
        out.append(np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, *words.tolist()])))
    return out


class _BatchNoise:
    """Per-scenario random streams, drawn in blocks and served as one (N, 6) array per step.

    Each scenario's draws come from its own generator in a fixed order, so a scenario's
    run does not depend on the batch it is in.
    """

    PER_STEP = 6
    BLOCK = 256

    def __init__(self, rngs: list[np.random.Generator]):
        self.rngs = rngs
        self.buffer = np.empty((len(rngs), 0, self.PER_STEP))
        self.cursor = 0

    def take(self, keep: np.ndarray) -> None:
        self.rngs = [self.rngs[i] for i in keep.tolist()]
        self.buffer = self.buffer[keep]

    def next(self) -> np.ndarray:
        if self.cursor >= self.buffer.shape[1]:
            self.buffer = np.stack([g.standard_normal((self.BLOCK, self.PER_STEP)) for g in self.rngs])
            self.cursor = 0
        self.cursor += 1
        return self.buffer[:, self.cursor - 1]


#: Compact the batch when fewer than this share of its rows are still running.
COMPACT_BELOW = 0.85


def _take_rows(obj, keep: np.ndarray, n: int) -> None:
    """Keep rows ``keep`` of every per-vehicle array attribute of ``obj`` (first axis n)."""
    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == n:
            setattr(obj, name, value[keep])
    if hasattr(obj, "_rows"):
        obj._rows = np.arange(keep.size)


def run_scenarios(scen: Scenarios, rngs: list[np.random.Generator] | None, record: bool
                  ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Step valid scenarios to the end; returns (scores, trajectories)."""
    m = scen.mission
    spec, dt, n = m.vehicle, m.dt, scen.n
    lx, ly = m.launch
    heading0 = np.arctan2(m.waypoints[0][0] - lx, m.waypoints[0][1] - ly) if m.waypoints else 0.0
    state = VehicleState.at_rest(np.full(n, float(lx)), np.full(n, float(ly)), np.full(n, heading0),
                                 scen.battery0 * spec.battery_wh)
    noise = _BatchNoise(rngs) if rngs is not None else None
    nav = Navigation(n, spec)
    autonomy = Autonomy(scen)
    scorer = Scorer(scen)
    active = np.ones(n, dtype=bool)
    surfaced = np.zeros(n, dtype=bool)
    drift_e = np.zeros(n)
    drift_n = np.zeros(n)
    frames: list[np.ndarray] = []
    steps = int(np.ceil(m.time_limit_s / dt))
    out = np.full((n, len(metric_names(m))), np.nan)
    where = np.arange(n)  # original row of each row still stepped
    for k in range(steps + 1):
        if not record and active.size >= 64 and active.sum() < COMPACT_BELOW * active.size:
            # drop finished runs so the rest step faster: score them now, keep their rows
            done = ~active
            out[where[done]] = scorer.scores(autonomy)[done]
            keep = np.flatnonzero(active)
            scen = scen.select(keep)
            for obj in (state, nav, autonomy, scorer):
                _take_rows(obj, keep, active.size)
            autonomy.scen = scorer.scen = scen
            if noise is not None:
                noise.take(keep)
            drift_e, drift_n, surfaced, where = drift_e[keep], drift_n[keep], surfaced[keep], where[keep]
            active = np.ones(keep.size, dtype=bool)
            n = keep.size
        t = k * dt
        contacts = sense(state.x, state.y, state.heading, scen.obstacle_edges, scen.barriers, spec)
        battery = state.energy_wh / spec.battery_wh
        ex, ey = nav.estimate(state.x, state.y)
        ce, cn = tidal_current(m.current, scen.start_time + t)
        nogo_est = rect_signed_distance(ex, ey, scen.nogo) if scen.nogo.shape[1] else None
        obs = Observation(t, ex, ey, state.heading, battery, contacts.x + (ex - state.x)[:, None],
                          contacts.y + (ey - state.y)[:, None], contacts.distance, contacts.detected, ce, cn,
                          nogo_est)
        cmd = autonomy.step(obs, dt, active)
        step_m = np.hypot(state.surge, state.sway) * dt
        nogo_true = nogo_est if noise is None else None  # without navigation error estimate == truth
        ended = scorer.update(t, state.x, state.y, battery, surfaced, autonomy.returning, contacts.distance,
                              contacts.detected, step_m, active, nogo_true)
        if record:
            frames.append(np.column_stack([np.full(n, t), state.x, state.y, state.heading, state.surge, battery,
                                           surfaced, autonomy.goal_kind]).astype(np.float32))
        active &= ~ended
        if not np.any(active) or k == steps:
            break
        surfaced = cmd.surface & active
        z = noise.next() if noise is not None else None
        if z is not None:
            # slowly varying unpredicted current: first-order Gauss-Markov, 10-minute correlation
            a = np.exp(-dt / 600.0)
            s = m.current.perturbation * np.sqrt(1 - a * a)
            drift_e = a * drift_e + s * z[:, 0]
            drift_n = a * drift_n + s * z[:, 1]
        step_vehicle(state, spec, cmd.heading, cmd.speed, ce + drift_e, cn + drift_n, dt, active)
        nav.step(dt, surfaced, None if z is None else z[:, 2:])
    out[where] = scorer.scores(autonomy)
    scores = out
    trajs = []
    if record:
        stack = np.stack(frames, axis=1)  # (n, steps, fields)
        for i in range(n):
            last = int(np.searchsorted(stack[i, :, 0], scorer.end_time[i], side="right"))
            trajs.append(stack[i, :max(last, 1)])
    return scores, trajs
