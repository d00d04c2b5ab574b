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

from rapt.errors import InputError
from sim.uuv.autonomy import Autonomy, Observation
from sim.uuv.bias import bias_arrays
from sim.uuv.contact_memory import ContactMemory
from sim.uuv.environment import tidal_current
from sim.uuv.geometry import rect_signed_distance
from sim.uuv.interface import decode_command, encode_command
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.scenario import Scenarios, make_scenarios
from sim.uuv.scoring import MODE_NAMES, Scorer, modes_from_scores
from sim.uuv.world import Telemetry, World, scenario_generators

__all__ = ["Result", "simulate", "run_scenarios", "TRAJECTORY_FIELDS"]

#: Per-step columns of a recorded trajectory.
#: ``speed`` and ``yaw_rate`` are the vehicle's through-water surge and turn rate; ``heading_cmd``
#: and ``speed_cmd`` the set-point it was given after the step, as MAVLink carried it.
TRAJECTORY_FIELDS = (
    "t",
    "x",
    "y",
    "heading",
    "energy_hj",
    "surfaced",
    "speed",
    "goal",
    "yaw_rate",
    "heading_cmd",
    "speed_cmd",
)


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

    def trajectory(self, row: int) -> np.ndarray | None:
        """Row ``row``'s trajectory (None for an invalid row), of a batch simulated with ``trajectories=True``."""
        if self.trajectories is None:
            raise InputError("trajectories: this batch was simulated without them; pass trajectories=True")
        return self.trajectories[row]


def simulate(
    mission: Mission,
    X: np.ndarray,
    seed: int = 0,
    stochastic: bool = False,
    trajectories: bool = False,
    bias=None,
    surrogate=None,
    plant: Vehicle | None = None,
    driver=None,
) -> Result:
    """Simulate unit-cube scenarios ``X`` (N, mission.dim) of ``mission``.

    ``stochastic`` switches on navigation drift and current perturbations, seeded per
    scenario from ``seed`` and the row's own values, so a row gives the same run alone or
    in any batch.  ``bias`` (a :class:`sim.uuv.bias.Bias`, or one per row) flies the scenarios
    with a biased vehicle and range while the autonomy plans unbiased; None or the
    neutral bias gives exactly the unbiased results.  ``surrogate`` (a
    :class:`sim.uuv.imitation.surrogate.Surrogate`) flies the vehicles in place of the expert.
    ``plant`` (a :class:`sim.uuv.mission.Vehicle`) flies the vehicles with its dynamics,
    power and battery while the autonomy plans with ``mission.vehicle``: how runs of the
    plan's autonomy go on a vehicle calibrated from logs (``rapt-plan calibrate``); None or
    a plant equal to ``mission.vehicle`` gives exactly the results without one.
    ``driver(scen)`` builds the back-seat in place of the expert autonomy, e.g. a
    :class:`sim.uuv.legs.LegAutonomy` flying a calibration run's legs (not with ``surrogate``).
    """
    if driver is not None and surrogate is not None:
        raise InputError("driver: give a driver or a surrogate, not both")
    scen = make_scenarios(mission, X)
    names, types = metric_names(mission), metric_types(mission)
    scores = np.full((scen.n, len(names)), np.nan)
    trajs: list[np.ndarray | None] | None = [None] * scen.n if trajectories else None
    rows = np.flatnonzero(scen.valid)
    if rows.size:
        sub = scen.select(rows)
        rngs = scenario_generators(np.asarray(X, dtype=float)[rows], seed) if stochastic else None
        got, tr = run_scenarios(
            sub,
            rngs,
            trajectories,
            bias_arrays(bias, scen.n).select(rows),
            plant=plant,
            **({"driver": driver} if surrogate is None else surrogate.driver_options()),
        )
        scores[rows] = got
        if trajs is not None:  # trajectories asked for
            for r, t in zip(rows.tolist(), tr):
                trajs[r] = t
    return Result(scores, modes_from_scores(scores), scen.valid.copy(), list(scen.invalid_reason), names, types, trajs)


#: Compact the batch when fewer than this share of its rows are still running.
COMPACT_BELOW = 0.85


def _take_rows(obj, keep: np.ndarray, n: int) -> None:
    """Keep rows ``keep`` of every per-vehicle array attribute of ``obj`` (first axis n), and of its contact memory."""
    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == n:
            setattr(obj, name, value[keep])
        elif isinstance(value, ContactMemory):
            _take_rows(value, keep, n)
    if hasattr(obj, "_rows"):
        obj._rows = np.arange(keep.size)


def run_scenarios(
    scen: Scenarios,
    rngs: list[np.random.Generator] | None,
    record: bool,
    bias=None,
    *,
    driver=None,
    scan_beams: int = 0,
    on_step=None,
    plant: Vehicle | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Step valid scenarios to the end; returns (scores, trajectories).

    Per step: the world reports telemetry at MAVLink precision, the autonomy decides on it,
    the referee scores it, and the set-point — rounded as MAVLink carries it — moves the world.
    ``driver(scen)`` builds another back-seat in place of the expert :class:`Autonomy`
    (a learned one needs ``scan_beams``); ``on_step(obs, cmd, active, driver)`` sees every
    decision (the batch is then never compacted, so rows keep their place).
    ``plant`` is the vehicle the world flies (default ``scen.mission.vehicle``; see :func:`simulate`).
    """
    m = scen.mission
    dt, n = m.dt, scen.n
    world = World(scen, rngs, bias, scan_beams, plant)
    autonomy = Autonomy(scen) if driver is None else driver(scen)
    scorer = Scorer(scen)
    active = np.ones(n, dtype=bool)
    frames: list[np.ndarray] = []
    steps = int(np.ceil(m.time_limit_s / dt))
    out = np.full((n, len(metric_names(m))), np.nan)
    where = np.arange(n)  # original row of each row still stepped
    for k in range(steps + 1):
        if not record and on_step is None and active.size >= 64 and active.sum() < COMPACT_BELOW * active.size:
            # drop finished runs so the rest step faster: score them now, keep their rows
            done = ~active
            out[where[done]] = scorer.scores(autonomy.wp_aborted, autonomy.return_reason)[done]
            keep = np.flatnonzero(active)
            world.take(keep)
            for obj in (autonomy, scorer):
                _take_rows(obj, keep, active.size)
            autonomy.scen = scorer.scen = world.scen
            where = where[keep]
            active = np.ones(keep.size, dtype=bool)
        t = k * dt
        tel = world.telemetry(t)
        nogo = rect_signed_distance(tel.x, tel.y, world.scen.nogo) if world.scen.nogo.shape[1] else None
        obs = observation(tel, world.scen, nogo if tel.est_x is tel.x else None)
        cmd = autonomy.step(obs, dt, active)
        if on_step is not None:
            on_step(obs, cmd, active, autonomy)
        ended = scorer.update_from(tel, active, nogo)
        heading, speed, surface = decode_command(*encode_command(cmd.heading, cmd.speed, cmd.surface))
        if record:
            frames.append(
                np.column_stack(
                    [
                        np.full(tel.x.shape, t),
                        tel.x,
                        tel.y,
                        tel.heading,
                        tel.energy_hj,
                        tel.surfaced,
                        world.state.surge,
                        autonomy.goal_kind,
                        world.state.yaw_rate,
                        heading,
                        speed,
                    ]
                )
            )
        active &= ~ended
        if not np.any(active) or k == steps:
            break
        world.advance(t, heading, speed, surface, active)
    out[where] = scorer.scores(autonomy.wp_aborted, autonomy.return_reason)
    trajs = []
    if record:
        stack = np.stack(frames, axis=1)  # (n, steps, fields)
        for i in range(stack.shape[0]):
            last = int(np.searchsorted(stack[i, :, 0], scorer.end_time[i], side="right"))
            trajs.append(stack[i, : max(last, 1)])
    return out, trajs


def observation(tel: Telemetry, scen: Scenarios, nogo: np.ndarray | None = None) -> Observation:
    """What the back-seat knows at a step: the telemetry plus its tide table and map.

    ``nogo`` may pass distances to the no-go areas already measured from ``tel.est_x/y``.
    """
    ce, cn = tidal_current(scen.mission.current, scen.start_time + tel.t)
    if nogo is None and scen.nogo.shape[1]:
        nogo = rect_signed_distance(tel.est_x, tel.est_y, scen.nogo)
    return Observation(
        tel.t,
        tel.est_x,
        tel.est_y,
        tel.heading,
        tel.battery,
        tel.contact_x,
        tel.contact_y,
        tel.contact_distance,
        tel.detected,
        ce,
        cn,
        nogo,
        tel.scan,
    )
