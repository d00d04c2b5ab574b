"""Short open-loop segments of logged runs, replayed through the simulator's vehicle and tide models.

Re-simulating a logged run closed loop under a trial bias or vehicle model jumps with it:
a waypoint reached one step earlier, a no-go area avoided on the other side, and the rest
of the run differs.  The log holds more than the track, though: the set-point the
back-seat gave at every step.  So each run is cut into segments of :data:`SEGMENT_STEPS`
steps; each starts from the logged state and is flown *open loop* on the logged set-points
(:func:`sim.uuv.vehicle.step_vehicle`, :func:`sim.uuv.environment.tidal_current`).  No
autonomy decision sits inside, so the predicted positions, headings and energy are smooth
in the parameters, every log counts, and a truncated one counts as far as it goes.
Segments are short so that a real vehicle's unmodelled disturbances do not accumulate.
Used by the execution-bias fit (:mod:`planner.biasfit`) and the vehicle calibration
(:mod:`planner.calibrate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.uuv.bias import Bias
from sim.uuv.environment import tidal_current
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.vehicle import SWAY_COUPLING, VehicleState, step_vehicle

__all__ = ["Segments", "segment_batch", "replay", "SEGMENT_STEPS"]

#: Steps per open-loop segment (2 s steps: two minutes of flight).
SEGMENT_STEPS = 60


@dataclass
class Segments:
    """Open-loop segments of logged runs, as (N, L) arrays; ``valid`` masks padding."""

    start: dict  # x, y, heading, surge, sway, yaw_rate, energy_hj, t: (N,)
    t: np.ndarray  # (N, L) time of each step's start
    start_time: np.ndarray  # (N,) the scenario's start time (s after midnight)
    heading_cmd: np.ndarray
    speed_cmd: np.ndarray
    obs_x: np.ndarray  # (N, L) logged position after each step
    obs_y: np.ndarray
    obs_energy_wh: np.ndarray  # (N, L) energy used since the segment's start
    obs_heading: np.ndarray  # (N, L) logged heading after each step (rad)
    valid: np.ndarray
    run: np.ndarray  # (N,) index of the run each segment comes from


def _sway(steps: np.ndarray, mission: Mission) -> np.ndarray:
    """Sway rebuilt from logged surge and turn rate with the vehicle model's sway equation."""
    dt = mission.dt
    a_v = 1.0 - np.exp(-dt * mission.vehicle.sway_damping)
    v = np.zeros(steps.shape[0])
    for k in range(1, steps.shape[0]):
        u, r = steps[k, 6], steps[k, 7]
        v[k] = v[k - 1] + (-SWAY_COUPLING * u * r - v[k - 1]) * a_v
    return v


def segment_batch(mission: Mission, runs: list, start_times: list[float], length: int = SEGMENT_STEPS) -> Segments:
    """Cut every run (a :class:`planner.logs.LoggedRun`) into segments of ``length`` steps.

    A step counts when the next step follows it by exactly ``mission.dt`` (no gap from a
    lost chunk) and the set-point flown after it is in the log.
    """
    dt = mission.dt
    rows = []
    for i, (run, t0) in enumerate(zip(runs, start_times)):
        s, sp = run.steps, run.setpoints
        if s.shape[0] < 2:
            continue
        sway = _sway(s, mission)
        ok = (np.abs(np.diff(s[:, 0]) - dt) < 1e-6) & np.isfinite(sp[:-1, 1])
        k = 0
        while k < len(ok):
            if not ok[k]:
                k += 1
                continue
            end = k
            while end < len(ok) and ok[end] and end - k < length:
                end += 1
            rows.append((i, t0, k, end, s, sp, sway))
            k = end
    n = len(rows)
    L = length
    t = np.zeros((n, L))
    hc, sc = np.zeros((n, L)), np.zeros((n, L))
    ox, oy, oe, oh = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    valid = np.zeros((n, L), dtype=bool)
    start = {key: np.zeros(n) for key in ("x", "y", "heading", "surge", "sway", "yaw_rate")}
    st, run_index = np.zeros(n), np.zeros(n, dtype=np.int64)
    for j, (i, t0, k, end, s, sp, sway) in enumerate(rows):
        m = end - k
        start["x"][j], start["y"][j], start["heading"][j] = s[k, 1], s[k, 2], s[k, 3]
        start["surge"][j], start["sway"][j], start["yaw_rate"][j] = s[k, 6], sway[k], s[k, 7]
        st[j], run_index[j] = t0, i
        t[j, :m] = s[k:end, 0]
        hc[j, :m], sc[j, :m] = sp[k:end, 0], sp[k:end, 1]
        ox[j, :m], oy[j, :m] = s[k + 1 : end + 1, 1], s[k + 1 : end + 1, 2]
        oe[j, :m] = (s[k + 1 : end + 1, 4] - s[k, 4]) / 36.0
        oh[j, :m] = s[k + 1 : end + 1, 3]
        valid[j, :m] = True
    return Segments(start, t, st, hc, sc, ox, oy, oe, oh, valid, run_index)


def replay(
    mission: Mission, seg: Segments, bias: Bias | None = None, vehicle: Vehicle | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Predicted (x, y, energy used, heading) of every segment step: (N, L) each.

    ``bias`` (default neutral) biases the vehicle and tide; ``vehicle`` (default the
    mission's) is the vehicle model flown.
    """
    bias = bias or Bias()
    n, L = seg.t.shape
    spec, dt = vehicle or mission.vehicle, mission.dt
    s = VehicleState(
        seg.start["x"].copy(),
        seg.start["y"].copy(),
        seg.start["heading"].copy(),
        seg.start["surge"].copy(),
        seg.start["sway"].copy(),
        seg.start["yaw_rate"].copy(),
        np.zeros(n),
    )
    px, py, pe, ph = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    course = np.deg2rad(bias.heading)
    for j in range(L):
        moving = seg.valid[:, j]
        ce, cn = tidal_current(
            mission.current, seg.start_time + bias.start_time + seg.t[:, j], bias.current_scale, bias.current_offset
        )
        step_vehicle(
            s,
            spec,
            seg.heading_cmd[:, j],
            seg.speed_cmd[:, j],
            ce,
            cn,
            dt,
            moving,
            speed_scale=bias.speed,
            course_bias=course,
            energy_scale=bias.battery,
        )
        px[:, j], py[:, j], pe[:, j], ph[:, j] = s.x, s.y, -s.energy_wh, s.heading
    return px, py, pe, ph
