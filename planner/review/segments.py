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

A real vehicle's reports do not land on the back-seat's decision period: a radio link or a
busy autopilot moves each by a fraction of a second, and some never arrive.  The back-seat
decides on the first report of each period (:class:`planner.common.telemetry.TrackSampler`
and the back-seat's decision clock share that rule), so the logged steps are the vehicle's
own report times, ``dt`` apart give or take the wait for a report.  Each step is replayed
over its own logged length (:func:`step_lengths`): the set-point flown after a report was
flown from that report's time to the next one's, which is what the vehicle did; the
vehicle-paced replay's physics sub-steps divide each step's own length.  This is more
faithful than resampling the log onto the decision grid by interpolation, which would
invent positions between reports (cutting the corner of every turn), blur the instant
each set-point took over across two grid steps, and put the energy counter's
whole-hectojoule steps where they were not reported.  A step counts while its length is
within :data:`MAX_STEP_SHARE` of ``dt``: a longer one means a decision period passed with
no report (a gap in the link or the log: the vehicle flew an old set-point, or, past
ArduSub's 3 s, none), which the logged set-points do not describe.  Such gaps, dropped
reports and late set-points (:data:`MAX_SETPOINT_DELAY_S`) cut a segment short; the rest
of the log still counts.  Steps exactly ``dt`` apart (within 1e-6 s: every lock-step log)
are replayed with ``dt`` itself, so those logs give the figures they always gave.
Used by the execution-bias fit (:mod:`planner.review.biasfit`) and the vehicle calibration
(:mod:`planner.review.calibrate`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sim.uuv.bias import Bias, compose
from sim.uuv.environment import biased_tide, tidal_current
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.vehicle import SWAY_COUPLING, VehicleState, reached_speed, step_vehicle, surface_limited

__all__ = [
    "Segments",
    "segment_batch",
    "replay",
    "SEGMENT_STEPS",
    "PACED_SUBSTEPS",
    "MAX_SETPOINT_DELAY_S",
    "MAX_STEP_SHARE",
    "substeps_of",
    "step_lengths",
    "replayable_steps",
]

#: Steps per open-loop segment (2 s steps: two minutes of flight).
SEGMENT_STEPS = 60
#: Steps of set-points before each segment kept to warm up a vector speed loop's slow part: it
#: follows the commands alone (not the position), so the history says where it stands at the
#: segment's start (a minute at 2 s steps: four of ArduSub's slow time constants).
HISTORY_STEPS = 30
#: Physics sub-steps per step when replaying a vehicle-paced run (0.2 s at 2 s steps).
PACED_SUBSTEPS = 10
#: A step whose set-point reached the bus more than this many vehicle seconds after it is not
#: replayed: the vehicle flew the previous set-point for a noticeable share of the step (or,
#: unanswered for 3 s, stopped), which the logged set-point does not say.
MAX_SETPOINT_DELAY_S = 0.3
#: A step counts while its logged length is within this share of ``mission.dt`` (at 2 s:
#: 1 to 3 s).  Longer, a decision period passed with no report and the vehicle flew an old
#: set-point (or, past ArduSub's 3 s velocity timeout, none); shorter, the reports are not
#: the back-seat's steps.  Report jitter of a few tenths of a second stays well inside.
MAX_STEP_SHARE = 0.5


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
    step_dt: np.ndarray | None = None  # (N, L) each step's own length, s (None: mission.dt throughout)
    surfaced: np.ndarray | None = None  # (N, L) bool: the vehicle reported itself surfaced at the step's end
    # the HISTORY_STEPS set-points flown before each segment (oldest first; invalid: no set-point, or padding)
    history: dict | None = None  # heading_cmd, speed_cmd, step_dt, surfaced, valid: (N, H)

    def repeated(self, p: int) -> Segments:
        """These segments ``p`` times over, copy after copy: one copy per trial of a batched replay."""
        n = self.valid.shape[0]

        def rep(v):
            if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == n:
                return np.concatenate([v] * p, axis=0)
            if isinstance(v, dict):
                return {key: rep(x) for key, x in v.items()}
            return v

        return Segments(**{f.name: rep(getattr(self, f.name)) for f in dataclasses.fields(self)})


def substeps_of(run) -> int:
    """Physics sub-steps per step to replay ``run`` with: :data:`PACED_SUBSTEPS` for a vehicle-paced run."""
    return PACED_SUBSTEPS if getattr(run, "meta", {}).get("pacing") == "vehicle" else 1


def step_lengths(t: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Each step's length (from step k's time to step k+1's, ``dt`` itself where within 1e-6 s of it)
    and whether it counts (within :data:`MAX_STEP_SHARE` of ``dt``): (n - 1,) each."""
    raw = np.diff(np.asarray(t, dtype=float))
    exact = np.abs(raw - dt) < 1e-6
    lengths = np.where(exact, dt, raw)
    return lengths, exact | (np.abs(raw - dt) <= MAX_STEP_SHARE * dt)


def replayable_steps(run, dt: float) -> np.ndarray:
    """Per step but the last of ``run``: its length counts (:func:`step_lengths`) and the set-point flown after it is logged."""
    s, sp = run.steps, run.setpoints
    if s.shape[0] < 2:
        return np.zeros(0, dtype=bool)
    return step_lengths(s[:, 0], dt)[1] & np.isfinite(sp[:-1, 1])


def _ground_velocity(
    steps: np.ndarray, dt: float, central: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per step: ground velocity (east, north), the time whose tide it carries, and whether it exists.

    Backward (the step before, as the lock-step simulator moves) or central (around the
    step, a continuously moving vehicle; forward at a run's first step) differences of
    the logged positions over each step's own length; only over steps that count
    (:func:`step_lengths`).
    """
    n = steps.shape[0]
    t, x, y = steps[:, 0], steps[:, 1], steps[:, 2]
    ve, vn, tt = np.zeros(n), np.zeros(n), t.copy()
    ok = np.zeros(n, dtype=bool)
    if n < 2:
        return ve, vn, tt, ok
    h, step_ok = step_lengths(t, dt)  # step k -> k+1
    h = np.where(step_ok, h, dt)  # a gap's velocity is never used: any divisor will do
    back = np.zeros(n, dtype=bool)
    back[1:] = step_ok
    ve[1:], vn[1:] = np.diff(x) / h, np.diff(y) / h
    tt[1:] = t[:-1]
    ok = back.copy()
    if central:
        both = np.zeros(n, dtype=bool)
        both[1:-1] = step_ok[:-1] & step_ok[1:]
        span = h[:-1] + h[1:]  # 2 dt exactly where both steps are dt
        ve = np.where(both, np.concatenate([[0.0], (x[2:] - x[:-2]) / span, [0.0]]), ve)
        vn = np.where(both, np.concatenate([[0.0], (y[2:] - y[:-2]) / span, [0.0]]), vn)
        tt = np.where(both, t, tt)
        # where no step comes before (a run's first), the step after: a vehicle at rest drifts with the tide
        fwd = np.zeros(n, dtype=bool)
        fwd[:-1] = step_ok & ~back[:-1]
        ve = np.where(fwd, np.concatenate([np.diff(x) / h, [0.0]]), ve)
        vn = np.where(fwd, np.concatenate([np.diff(y) / h, [0.0]]), vn)
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
    """Sway rebuilt from the surge and logged turn rate with the vehicle model's sway equation, step by step."""
    dt = mission.dt
    a_v = np.full(steps.shape[0], 1.0 - np.exp(-dt * mission.vehicle.sway_damping))
    if steps.shape[0] > 1:  # a step of its own length (a gap's length is the period's)
        h, ok = step_lengths(steps[:, 0], dt)
        own = ok & (h != dt)
        a_v[1:][own] = 1.0 - np.exp(-h[own] * mission.vehicle.sway_damping)
    v = np.zeros(steps.shape[0])
    for k in range(1, steps.shape[0]):
        u, r = surge[k], steps[k, 7]
        v[k] = v[k - 1] + (-SWAY_COUPLING * u * r - v[k - 1]) * a_v[k]
    return v


def segment_batch(mission: Mission, runs: list, start_times: list[float], length: int = SEGMENT_STEPS) -> Segments:
    """Cut every run (a :class:`planner.review.logs.LoggedRun`) into segments of ``length`` steps.

    A step counts when the next step follows it within :data:`MAX_STEP_SHARE` of
    ``mission.dt`` (no gap from lost reports or a lost chunk; it is replayed over its own
    length), the set-point flown after it is in the log, and that set-point answered this
    step within :data:`MAX_SETPOINT_DELAY_S` (``LoggedRun.setpoint_delay_s``).
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
        ok = replayable_steps(run, dt)
        lengths = step_lengths(s[:, 0], dt)[0]
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
            rows.append((i, t0, k, end, s, sp, sway, nsub, ground, lengths))
            k = end
    n = len(rows)
    L = length
    t = np.zeros((n, L))
    hc, sc = np.zeros((n, L)), np.zeros((n, L))
    ox, oy, oe, oh = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    step_dt = np.full((n, L), dt)
    surfaced = np.zeros((n, L), dtype=bool)
    H = HISTORY_STEPS
    hist = {
        "heading_cmd": np.zeros((n, H)),
        "speed_cmd": np.zeros((n, H)),
        "step_dt": np.full((n, H), dt),
        "surfaced": np.zeros((n, H), dtype=bool),
        "valid": np.zeros((n, H), dtype=bool),
    }
    valid = np.zeros((n, L), dtype=bool)
    start = {key: np.zeros(n) for key in ("x", "y", "heading", "surge", "sway", "yaw_rate")}
    st, run_index = np.zeros(n), np.zeros(n, dtype=np.int64)
    nsubs = np.ones(n, dtype=np.int64)
    gr = {"ve": np.zeros(n), "vn": np.zeros(n), "t_tide": np.zeros(n), "ok": np.zeros(n, dtype=bool)}
    for j, (i, t0, k, end, s, sp, sway, nsub, ground, lengths) in enumerate(rows):
        m = end - k
        nsubs[j] = nsub
        for key, col in zip(("ve", "vn", "t_tide", "ok"), ground):
            gr[key][j] = col[k]
        start["x"][j], start["y"][j], start["heading"][j] = s[k, 1], s[k, 2], s[k, 3]
        start["surge"][j], start["sway"][j], start["yaw_rate"][j] = s[k, 6], sway[k], s[k, 7]
        st[j], run_index[j] = t0, i
        t[j, :m] = s[k:end, 0]
        step_dt[j, :m] = lengths[k:end]
        hc[j, :m], sc[j, :m] = sp[k:end, 0], sp[k:end, 1]
        ox[j, :m], oy[j, :m] = s[k + 1 : end + 1, 1], s[k + 1 : end + 1, 2]
        oe[j, :m] = (s[k + 1 : end + 1, 4] - s[k, 4]) / 36.0
        oh[j, :m] = s[k + 1 : end + 1, 3]
        surfaced[j, :m] = s[k + 1 : end + 1, 5] > 0.5  # the world rises before it moves: the state after the step
        a = max(k - H, 0)
        w = k - a
        if w:
            hist["heading_cmd"][j, H - w :], hist["speed_cmd"][j, H - w :] = sp[a:k, 0], sp[a:k, 1]
            hist["step_dt"][j, H - w :] = np.where(np.isfinite(lengths[a:k]), lengths[a:k], dt)
            hist["surfaced"][j, H - w :] = s[a + 1 : k + 1, 5] > 0.5
            hist["valid"][j, H - w :] = np.isfinite(sp[a:k, 1]) & (np.abs(lengths[a:k] - dt) <= MAX_STEP_SHARE * dt)
        valid[j, :m] = True
    return Segments(start, t, st, hc, sc, ox, oy, oe, oh, valid, run_index, nsubs, gr, step_dt, surfaced, hist)


def replay(
    mission: Mission, seg: Segments, bias: Bias | None = None, vehicle: Vehicle | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Predicted (x, y, energy used, heading) of every segment step: (N, L) each.

    ``bias`` (default neutral) biases the vehicle and tide; ``vehicle`` (default the
    mission's) is the vehicle model flown.  Each segment starts from its logged state,
    its surge rebuilt from the logged ground velocity under this bias's tide and course; each
    step is flown over its own logged length (``seg.step_dt``).  ``bias`` is relative to the
    mission's day bias (``Mission.execution_bias``), as in the world.
    """
    bias = compose(mission.execution_bias, bias or Bias())
    n, L = seg.t.shape
    spec, dt = vehicle or mission.vehicle, mission.dt
    course = np.deg2rad(bias.heading)

    def tide(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return biased_tide(mission.current, seg.start_time + bias.start_time + t, bias)

    surge = seg.start["surge"].copy()
    h0 = seg.start["heading"] + course
    we, wn = surge * np.sin(h0), surge * np.cos(h0)  # through water, where no ground velocity says better
    if seg.ground is not None:
        g = seg.ground
        ce, cn = tide(g["t_tide"])
        surge = np.where(g["ok"], (g["ve"] - ce) * np.sin(h0) + (g["vn"] - cn) * np.cos(h0), surge)
        we, wn = np.where(g["ok"], g["ve"] - ce, we), np.where(g["ok"], g["vn"] - cn, wn)
    s = VehicleState(
        seg.start["x"].copy(),
        seg.start["y"].copy(),
        seg.start["heading"].copy(),
        surge,
        seg.start["sway"].copy(),
        seg.start["yaw_rate"].copy(),
        np.zeros(n),
    )
    if spec.velocity_control == "vector":
        s.set_water_velocity(spec, we, wn, _slow_part(spec, seg, bias.speed, course))
    px, py, pe, ph = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    nsub = np.ones(n, dtype=np.int64) if seg.substeps is None else seg.substeps
    most = int(nsub.max()) if n else 1
    # the water at every (sub)step, computed whole (steps by segments: a bias may be one per segment)
    step_len = dt if seg.step_dt is None else seg.step_dt.T
    water = [tide(seg.t.T + q * (step_len / nsub)) for q in range(most)]
    for j in range(L):
        # each step over its own logged length (mission.dt itself, a scalar, wherever it is that)
        h = dt if seg.step_dt is None or bool(np.all(seg.step_dt[:, j] == dt)) else seg.step_dt[:, j].copy()
        sub_dt = h / nsub
        for q in range(most):
            moving = seg.valid[:, j] & (q < nsub)
            ce, cn = water[q][0][j], water[q][1][j]
            step_vehicle(
                s,
                spec,
                seg.heading_cmd[:, j],
                seg.speed_cmd[:, j],
                ce,
                cn,
                h if most == 1 else sub_dt,
                moving,
                speed_scale=bias.speed,
                course_bias=course,
                energy_scale=bias.battery,
                surfaced=None if seg.surfaced is None else seg.surfaced[:, j],
            )
        px[:, j], py[:, j], pe[:, j], ph[:, j] = s.x, s.y, -s.energy_wh, s.heading
    return px, py, pe, ph


def _slow_part(spec: Vehicle, seg: Segments, speed_scale: float, course: float) -> tuple[np.ndarray, np.ndarray] | None:
    """A vector loop's slow part at each segment's start, run over the set-points flown before it
    (``seg.history``); None without a history.  It follows the commands alone, so the log's
    commands say where it stands where its positions cannot."""
    h = seg.history
    if h is None or np.all(np.asarray(spec.slow_share) == 0):
        return None
    n, H = h["speed_cmd"].shape
    se, sn = np.zeros(n), np.zeros(n)
    for j in range(H):
        target = surface_limited(spec, reached_speed(spec, h["speed_cmd"][:, j]), h["surfaced"][:, j])
        target = spec.slow_share * target * speed_scale
        c = h["heading_cmd"][:, j] + course
        a = 1.0 - np.exp(-h["step_dt"][:, j] / spec.slow_time_constant_s)
        ok = h["valid"][:, j]
        se = np.where(ok, se + (target * np.sin(c) - se) * a, se)
        sn = np.where(ok, sn + (target * np.cos(c) - sn) * a, sn)
    return se, sn
