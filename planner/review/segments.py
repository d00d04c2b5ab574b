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

Only what any vehicle reports is used.  A segment's starting through-water surge is
rebuilt from the logged positions, not read from the log's speed column (ground speed
for a real or bare-autopilot vehicle, surge through water for the lock-step front-seat):
the ground velocity over the step before (lock-step) or around (vehicle-paced) the start,
minus the tide, projected on the heading — exact for the lock-step simulator, right to
first order for any vehicle.  A vehicle-paced run (a real vehicle, the bare autopilot)
moves continuously, so its segments are replayed in :data:`PACED_SUBSTEPS` sub-steps per
step with the set-point held; the lock-step front-seat steps by ``mission.dt`` as the
batch simulator does, and is replayed so.
Used by the execution-bias fit (:mod:`planner.review.biasfit`) and the vehicle calibration
(:mod:`planner.review.calibrate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.uuv.bias import Bias, compose
from sim.uuv.environment import tidal_current
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.vehicle import SWAY_COUPLING, VehicleState, step_vehicle

__all__ = [
    "Segments",
    "segment_batch",
    "replay",
    "SEGMENT_STEPS",
    "PACED_SUBSTEPS",
    "MAX_SETPOINT_DELAY_S",
    "substeps_of",
]

#: Steps per open-loop segment (2 s steps: two minutes of flight).
SEGMENT_STEPS = 60
#: Physics sub-steps per step when replaying a vehicle-paced run (0.2 s at 2 s steps).
PACED_SUBSTEPS = 10
#: A step whose set-point reached the bus more than this many vehicle seconds after it is not
#: replayed: the vehicle flew the previous set-point for a noticeable share of the step (or,
#: unanswered for 3 s, stopped), which the logged set-point does not say.
MAX_SETPOINT_DELAY_S = 0.3


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
    substeps: np.ndarray | None = None  # (N,) physics sub-steps per step (None: 1)
    # the logged ground velocity the start surge is rebuilt from, and the time whose tide it carries
    ground: dict | None = None  # ve, vn, t_tide: (N,); ok: (N,) bool (False: use start["surge"])


def substeps_of(run) -> int:
    """Physics sub-steps per step to replay ``run`` with: :data:`PACED_SUBSTEPS` for a vehicle-paced run."""
    return PACED_SUBSTEPS if getattr(run, "meta", {}).get("pacing") == "vehicle" else 1


def _ground_velocity(
    steps: np.ndarray, dt: float, central: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per step: ground velocity (east, north), the time whose tide it carries, and whether it exists.

    Backward (the step before, as the lock-step simulator moves) or central (around the
    step, a continuously moving vehicle; forward at a run's first step) differences of
    the logged positions; only over steps exactly ``dt`` apart.
    """
    n = steps.shape[0]
    t, x, y = steps[:, 0], steps[:, 1], steps[:, 2]
    ve, vn, tt = np.zeros(n), np.zeros(n), t.copy()
    ok = np.zeros(n, dtype=bool)
    if n < 2:
        return ve, vn, tt, ok
    step_ok = np.abs(np.diff(t) - dt) < 1e-6  # step k -> k+1
    back = np.zeros(n, dtype=bool)
    back[1:] = step_ok
    ve[1:], vn[1:] = np.diff(x) / dt, np.diff(y) / dt
    tt[1:] = t[:-1]
    ok = back.copy()
    if central:
        both = np.zeros(n, dtype=bool)
        both[1:-1] = step_ok[:-1] & step_ok[1:]
        ve = np.where(both, np.concatenate([[0.0], (x[2:] - x[:-2]) / (2 * dt), [0.0]]), ve)
        vn = np.where(both, np.concatenate([[0.0], (y[2:] - y[:-2]) / (2 * dt), [0.0]]), vn)
        tt = np.where(both, t, tt)
        # where no step comes before (a run's first), the step after: a vehicle at rest drifts with the tide
        fwd = np.zeros(n, dtype=bool)
        fwd[:-1] = step_ok & ~back[:-1]
        ve = np.where(fwd, np.concatenate([np.diff(x) / dt, [0.0]]), ve)
        vn = np.where(fwd, np.concatenate([np.diff(y) / dt, [0.0]]), vn)
        ok = back | both | fwd
    return ve, vn, tt, ok


def _surge_through_water(mission: Mission, steps: np.ndarray, start_time: float, central: bool) -> np.ndarray:
    """Through-water surge per step from the logged positions and the tide (the logged column where there is none)."""
    ve, vn, tt, ok = _ground_velocity(steps, mission.dt, central)
    ce, cn = tidal_current(mission.current, start_time + tt)
    h = steps[:, 3]
    u = (ve - ce) * np.sin(h) + (vn - cn) * np.cos(h)
    return np.where(ok, u, steps[:, 6])


def _sway(steps: np.ndarray, mission: Mission, surge: np.ndarray) -> np.ndarray:
    """Sway rebuilt from the surge and logged turn rate with the vehicle model's sway equation."""
    dt = mission.dt
    a_v = 1.0 - np.exp(-dt * mission.vehicle.sway_damping)
    v = np.zeros(steps.shape[0])
    for k in range(1, steps.shape[0]):
        u, r = surge[k], steps[k, 7]
        v[k] = v[k - 1] + (-SWAY_COUPLING * u * r - v[k - 1]) * a_v
    return v


def segment_batch(mission: Mission, runs: list, start_times: list[float], length: int = SEGMENT_STEPS) -> Segments:
    """Cut every run (a :class:`planner.review.logs.LoggedRun`) into segments of ``length`` steps.

    A step counts when the next step follows it by exactly ``mission.dt`` (no gap from a
    lost chunk), the set-point flown after it is in the log, and that set-point answered
    this step within :data:`MAX_SETPOINT_DELAY_S` (``LoggedRun.setpoint_delay_s``).
    """
    dt = mission.dt
    rows = []
    for i, (run, t0) in enumerate(zip(runs, start_times)):
        s, sp = run.steps, run.setpoints
        if s.shape[0] < 2:
            continue
        nsub = substeps_of(run)
        surge = _surge_through_water(mission, s, t0, central=nsub > 1)
        sway = _sway(s, mission, surge)
        ground = _ground_velocity(s, dt, central=nsub > 1)
        ok = (np.abs(np.diff(s[:, 0]) - dt) < 1e-6) & np.isfinite(sp[:-1, 1])
        delay = getattr(run, "setpoint_delay_s", None)
        if delay is not None and len(delay) == s.shape[0]:
            ok &= np.asarray(delay[:-1]) <= MAX_SETPOINT_DELAY_S
        k = 0
        while k < len(ok):
            if not ok[k]:
                k += 1
                continue
            end = k
            while end < len(ok) and ok[end] and end - k < length:
                end += 1
            rows.append((i, t0, k, end, s, sp, sway, nsub, ground))
            k = end
    n = len(rows)
    L = length
    t = np.zeros((n, L))
    hc, sc = np.zeros((n, L)), np.zeros((n, L))
    ox, oy, oe, oh = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    valid = np.zeros((n, L), dtype=bool)
    start = {key: np.zeros(n) for key in ("x", "y", "heading", "surge", "sway", "yaw_rate")}
    st, run_index = np.zeros(n), np.zeros(n, dtype=np.int64)
    nsubs = np.ones(n, dtype=np.int64)
    gr = {"ve": np.zeros(n), "vn": np.zeros(n), "t_tide": np.zeros(n), "ok": np.zeros(n, dtype=bool)}
    for j, (i, t0, k, end, s, sp, sway, nsub, ground) in enumerate(rows):
        m = end - k
        nsubs[j] = nsub
        for key, col in zip(("ve", "vn", "t_tide", "ok"), ground):
            gr[key][j] = col[k]
        start["x"][j], start["y"][j], start["heading"][j] = s[k, 1], s[k, 2], s[k, 3]
        start["surge"][j], start["sway"][j], start["yaw_rate"][j] = s[k, 6], sway[k], s[k, 7]
        st[j], run_index[j] = t0, i
        t[j, :m] = s[k:end, 0]
        hc[j, :m], sc[j, :m] = sp[k:end, 0], sp[k:end, 1]
        ox[j, :m], oy[j, :m] = s[k + 1 : end + 1, 1], s[k + 1 : end + 1, 2]
        oe[j, :m] = (s[k + 1 : end + 1, 4] - s[k, 4]) / 36.0
        oh[j, :m] = s[k + 1 : end + 1, 3]
        valid[j, :m] = True
    return Segments(start, t, st, hc, sc, ox, oy, oe, oh, valid, run_index, nsubs, gr)


def replay(
    mission: Mission, seg: Segments, bias: Bias | None = None, vehicle: Vehicle | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Predicted (x, y, energy used, heading) of every segment step: (N, L) each.

    ``bias`` (default neutral) biases the vehicle and tide; ``vehicle`` (default the
    mission's) is the vehicle model flown.  Each segment starts from its logged state,
    its surge rebuilt from the logged ground velocity under this bias's tide and course.
    ``bias`` is relative to the mission's day bias (``Mission.execution_bias``), as in the world.
    """
    bias = compose(mission.execution_bias, bias or Bias())
    n, L = seg.t.shape
    spec, dt = vehicle or mission.vehicle, mission.dt
    course = np.deg2rad(bias.heading)

    def tide(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return tidal_current(
            mission.current, seg.start_time + bias.start_time + t, bias.current_scale, bias.current_offset
        )

    surge = seg.start["surge"].copy()
    if seg.ground is not None:
        g = seg.ground
        ce, cn = tide(g["t_tide"])
        c = seg.start["heading"] + course
        surge = np.where(g["ok"], (g["ve"] - ce) * np.sin(c) + (g["vn"] - cn) * np.cos(c), surge)
    s = VehicleState(
        seg.start["x"].copy(),
        seg.start["y"].copy(),
        seg.start["heading"].copy(),
        surge,
        seg.start["sway"].copy(),
        seg.start["yaw_rate"].copy(),
        np.zeros(n),
    )
    px, py, pe, ph = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    nsub = np.ones(n, dtype=np.int64) if seg.substeps is None else seg.substeps
    most = int(nsub.max()) if n else 1
    sub_dt = dt / nsub
    for j in range(L):
        for q in range(most):
            moving = seg.valid[:, j] & (q < nsub)
            ce, cn = tide(seg.t[:, j] + q * sub_dt)
            step_vehicle(
                s,
                spec,
                seg.heading_cmd[:, j],
                seg.speed_cmd[:, j],
                ce,
                cn,
                dt if most == 1 else sub_dt,
                moving,
                speed_scale=bias.speed,
                course_bias=course,
                energy_scale=bias.battery,
            )
        px[:, j], py[:, j], pe[:, j], ph[:, j] = s.x, s.y, -s.energy_wh, s.heading
    return px, py, pe, ph
