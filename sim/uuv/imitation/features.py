"""What a learned back-seat sees and does: the features and actions of section 6.5.3.

Features, all in the vehicle frame (x along the bow, y to starboard) and in [-1, 1]:

* ``fuel`` — remaining charge, 2 b - 1;
* ``map`` — vectors to the next mission waypoint and to the recovery point, each as a
  direction (the vector over ``max(distance, near_m)``: a unit vector when far, shrinking
  to zero on arrival) and a distance (over the operational area's diagonal D, as far apart
  as two points in it can be: 2 d / D - 1).  Splitting direction from distance keeps the
  direction legible at any range, which is what steering needs, while the distance
  carries the fuel decision.  The waypoint's three are zero once every waypoint has been
  reached (the vehicle knows which it has reached) or given up (see the goal decision);
* ``current`` — the predicted tidal current the expert crabs against (its tide table), in
  the vehicle frame over the maximum speed (observation ``contacts``): the heading and
  through-water speed the expert commands depend on it;
* ``obstacles`` — what the expert knows of the obstacles, by the mission's observation model:

  - ``contacts`` (the default): the sonar contacts the expert remembers
    (:mod:`sim.uuv.contact_memory`): each closest point seen in the sonar's field of view
    (120 degrees, 100 m) within the last 30 s, nearest first, in up to :data:`MAX_SLOTS`
    slots of (closeness, forward, starboard): closeness ``(R - r) / R`` for a contact r
    metres away out to the sonar range R, and the unit vector to it; all 0 for an empty
    slot.  The expert steers on exactly these points, so a learner sees an obstacle
    exactly while the expert avoids it: not the one beside the path that the sonar never
    saw, and still the one it has turned away from;
  - ``scan``: a 360-beam, 1-degree range scan out to the sonar range (-1 touching, +1
    nothing within range), section 6.5.3's input.  It sees obstacles the expert has not
    seen and forgets those it has, so a learner cannot copy the expert's collisions;
* ``clock`` — mission time used, 2 t / limit - 1.  Not in the dissertation's list: our
  expert turns home when it runs out of time as well as fuel, and only the clock says so.

Actions: the commanded heading as a direction relative to the bow, ``(cos r, sin r)``; the
goal decision: +1 when the expert has given the mission waypoint up and heads home
(waypoints done, not enough fuel, not enough time), -1 while it still pursues it; and the
commanded through-water speed over the maximum speed.

Section 6.5.3 puts speed and heading in one vector ``(speed / max_speed) (cos r, sin r)``,
but a regression averages the vectors of neighbouring turns, and the shorter mean is a
slower vehicle, which spends less energy a metre (drag is cubic in speed) and reaches
waypoints the expert aborts.  With its own output the speed is learned as the expert holds
it, and the heading is the direction's angle whatever its length.

The expert latches its goal decision, and a memoryless regressor cannot imitate a latch
from the state alone: moments after turning on fuel the vehicle has the same charge and
distance from home as one that carries on, and averaging "go on" with "go home" stalls it.
So the learned back-seat latches its own decision too (as the expert's goal state does)
and, once home-bound, sees no waypoint pending, exactly the features of a vehicle that has
reached every waypoint.  The decision is learned from the features the expert takes it on,
not the scan (:func:`policy_heads`).

Every input is what the front-seat reports over MAVLink at MAVLink precision, so
features computed in the batch simulator and on the bus are the same numbers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from rapt.errors import InputError
from sim.uuv.angles import wrap_angle
from sim.uuv.contact_memory import CONTACT_MEMORY_S, ContactMemory
from sim.uuv.environment import tidal_current
from sim.uuv.mission import Mission
from sim.uuv.sonar import SCAN_BEAMS

__all__ = [
    "FeatureSpec",
    "OBSERVATIONS",
    "MAX_SLOTS",
    "contact_view",
    "obstacle_view",
    "predicted_current",
    "feature_spec",
    "features",
    "expert_action",
    "action_command",
    "advance_waypoints",
    "waypoint_target",
    "policy_heads",
    "ACTIONS",
    "GOAL",
    "SPEED",
]

FEATURE_VERSION = 5
#: Observation models: the expert's remembered sonar contacts, or section 6.5.3's 360-degree scan.
OBSERVATIONS = ("contacts", "scan")
#: Remembered contacts a learner sees at most, nearest first (the expert rarely knows more at once).
MAX_SLOTS = 4
#: Columns per contact slot: closeness, forward and starboard unit vector.
SLOT_COLUMNS = 3
#: Network outputs: heading direction (forward, starboard), the goal decision and the speed.
ACTIONS = 4
#: The action column of the goal decision (+1: give the waypoint up and head home).
GOAL = 2
#: The action column of the through-water speed over the maximum speed.
SPEED = 3
#: Within this distance a map vector shrinks linearly to zero (metres).
NEAR_M = 10.0


@dataclass(frozen=True)
class FeatureSpec:
    """How features are built for one mission: saved with a surrogate, checked on load."""

    version: int
    beams: int
    sonar_range_m: float
    map_scale_m: float
    near_m: float
    time_limit_s: float
    max_speed: float
    actions: int = ACTIONS
    observation: str = "contacts"
    slots: int = 0  # contact slots (observation "contacts")
    memory_s: float = CONTACT_MEMORY_S

    @property
    def view_size(self) -> int:
        """Columns of the obstacle view: the scan's beams or the contact slots."""
        return self.beams if self.observation == "scan" else SLOT_COLUMNS * self.slots

    @property
    def tide_size(self) -> int:
        """Columns of the predicted current (observation ``contacts``; section 6.5.3's scan has none)."""
        return 0 if self.observation == "scan" else 2

    @property
    def size(self) -> int:
        return 1 + 6 + self.tide_size + self.view_size + 1

    @property
    def waypoint(self) -> slice:
        """The pending waypoint's columns (direction and distance; all 0 when none is pending)."""
        return slice(1, 4)

    def waypoint_pending(self, F: np.ndarray) -> np.ndarray:
        """Rows of features ``F`` with a waypoint pending: where the goal decision is taken."""
        return np.any(np.asarray(F)[:, self.waypoint] != 0, axis=1)

    @property
    def sonar(self) -> slice:
        """The obstacle view's columns (the scan, or the remembered contacts)."""
        return slice(7 + self.tide_size, 7 + self.tide_size + self.view_size)

    @property
    def quiet(self) -> slice | None:
        """Columns that mostly read +1 (a scan in open water), which the networks skip when they do."""
        return self.sonar if self.observation == "scan" else None

    def names(self) -> list[str]:
        return (
            [
                "fuel",
                "waypoint_fwd",
                "waypoint_stbd",
                "waypoint_distance",
                "recovery_fwd",
                "recovery_stbd",
                "recovery_distance",
            ]
            + ["current_fwd", "current_stbd"][: self.tide_size]
            + (
                [f"sonar_{b}" for b in range(self.beams)]
                if self.observation == "scan"
                else [f"contact{k}_{c}" for k in range(self.slots) for c in ("closeness", "fwd", "stbd")]
            )
            + ["clock"]
        )

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> FeatureSpec:
        return cls(**d)

    def describe(self) -> str:
        """The observation model in a few words, for error messages."""
        if self.observation == "scan":
            return f"a {self.beams}-beam scan, no memory (feature version {self.version})"
        return f"{self.slots} remembered contacts, {self.memory_s:g} s memory (feature version {self.version})"


def policy_heads(spec: FeatureSpec) -> tuple[tuple[list[int] | None, list[int]], ...]:
    """Which features each network of a learned back-seat reads (``rapt.imitation.dagger.imitate(heads=)``).

    Heading and speed from every feature; the goal decision from the charge, the map vectors
    and the clock only — what the expert's goal selection reads (not the tide nor the obstacles).  Learned by the steering
    network, the decision leaned on the range scan (in the chapter 6 mission most early aborts of a
    single network fired on a sonar spike, its output with the scan cleared far below 0).
    """
    mission_level = list(range(7)) + [spec.size - 1]
    return ((None, [0, 1, SPEED]), (mission_level, [GOAL]))


def feature_spec(mission: Mission, observation: str = "contacts", beams: int = SCAN_BEAMS) -> FeatureSpec:
    """The features of a learned back-seat for ``mission`` under an observation model (:data:`OBSERVATIONS`)."""
    if observation not in OBSERVATIONS:
        raise InputError(f"observation: expected one of {', '.join(OBSERVATIONS)}, got {observation!r}")
    op = mission.operational_area
    scan = observation == "scan"
    return FeatureSpec(
        FEATURE_VERSION,
        beams if scan else 0,
        float(mission.vehicle.sonar_range_m),
        float(np.hypot(op.width, op.height)),
        NEAR_M,
        float(mission.time_limit_s),
        float(mission.vehicle.max_speed),
        ACTIONS,
        observation,
        0 if scan else min(len(mission.obstacles) + len(mission.barriers), MAX_SLOTS),
        CONTACT_MEMORY_S,
    )


def contact_view(
    spec: FeatureSpec,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    memory_x: np.ndarray | None,
    memory_y: np.ndarray | None,
    known: np.ndarray | None,
) -> np.ndarray:
    """(N, 3 slots) remembered contacts, nearest first: closeness and the unit vector to each, 0 when empty."""
    n = x.shape[0]
    out = np.zeros((n, SLOT_COLUMNS * spec.slots))
    if memory_x is None or memory_y is None or known is None or not spec.slots:
        return out
    dx, dy = memory_x - x[:, None], memory_y - y[:, None]
    r = np.hypot(dx, dy)
    close = np.where(known, np.clip((spec.sonar_range_m - r) / spec.sonar_range_m, 0.0, 1.0), 0.0)
    order = np.argsort(-close, axis=1, kind="stable")[:, : spec.slots]  # nearest first
    rows = np.arange(n)[:, None]
    c, dx, dy, r = close[rows, order], dx[rows, order], dy[rows, order], np.maximum(r[rows, order], 1.0)
    fwd, stbd = _body(dx, dy, heading[:, None])
    on = c > 0
    k = order.shape[1]
    out[:, 0 : SLOT_COLUMNS * k : SLOT_COLUMNS] = c
    out[:, 1 : SLOT_COLUMNS * k : SLOT_COLUMNS] = np.where(on, fwd / r, 0.0)
    out[:, 2 : SLOT_COLUMNS * k : SLOT_COLUMNS] = np.where(on, stbd / r, 0.0)
    return out


def advance_waypoints(mission: Mission, nxt: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Index of the next mission waypoint after a position report (reached within its radius)."""
    points = np.asarray(mission.waypoints, dtype=float).reshape(-1, 2)
    W = points.shape[0]
    if W == 0:
        return nxt
    w = np.minimum(nxt, W - 1)
    arrived = (nxt < W) & (np.hypot(points[w, 0] - x, points[w, 1] - y) <= mission.waypoint_radius)
    return nxt + arrived


def waypoint_target(mission: Mission, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, pending) of the next waypoint; ``pending`` is False once all are reached."""
    points = np.asarray(mission.waypoints, dtype=float).reshape(-1, 2)
    W = points.shape[0]
    if W == 0:
        z = np.zeros(nxt.shape[0])
        return z, z, np.zeros(nxt.shape[0], dtype=bool)
    w = np.minimum(nxt, W - 1)
    return points[w, 0], points[w, 1], nxt < W


def _body(dx: np.ndarray, dy: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World (east, north) vector into the vehicle frame (forward, starboard)."""
    s, c = np.sin(heading), np.cos(heading)
    return dx * s + dy * c, dx * c - dy * s


def features(
    spec: FeatureSpec,
    mission: Mission,
    t: float,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    battery: np.ndarray,
    view: np.ndarray,
    waypoint: tuple[np.ndarray, np.ndarray, np.ndarray],
    current: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(N, spec.size) float32 features from one step's reports (see the module docstring).

    ``view`` is the obstacle view: the scan's ranges in metres (observation ``scan``), or
    :func:`contact_view`'s columns (observation ``contacts``); ``current`` the predicted tide
    (east, north) in m/s that the expert crabs against (observation ``contacts``).
    """
    n = x.shape[0]
    out = np.empty((n, spec.size), dtype=np.float32)
    out[:, 0] = 2.0 * np.clip(battery, 0.0, 1.0) - 1.0
    wx, wy, pending = waypoint
    rx, ry = mission.recovery
    for col, (dx, dy, on) in ((1, (wx - x, wy - y, pending)), (4, (rx - x, ry - y, True))):
        dist = np.hypot(dx, dy)
        fwd, stbd = _body(dx, dy, heading)
        near = np.maximum(dist, spec.near_m)
        out[:, col] = np.where(on, fwd / near, 0.0)
        out[:, col + 1] = np.where(on, stbd / near, 0.0)
        out[:, col + 2] = np.where(on, np.clip(2.0 * dist / spec.map_scale_m - 1.0, -1.0, 1.0), 0.0)
    if spec.tide_size:
        if current is None:
            raise InputError("current: the contacts observation model needs the predicted tide (east, north)")
        fwd, stbd = _body(np.asarray(current[0], float), np.asarray(current[1], float), heading)
        out[:, 7] = np.clip(fwd / spec.max_speed, -1.0, 1.0)
        out[:, 8] = np.clip(stbd / spec.max_speed, -1.0, 1.0)
    if spec.observation == "scan":
        out[:, spec.sonar] = 2.0 * np.minimum(view, spec.sonar_range_m) / spec.sonar_range_m - 1.0
    else:
        out[:, spec.sonar] = view
    out[:, -1] = np.clip(2.0 * t / spec.time_limit_s - 1.0, -1.0, 1.0)
    return out


def expert_action(
    spec: FeatureSpec,
    heading: np.ndarray,
    cmd_heading: np.ndarray,
    cmd_speed: np.ndarray,
    home: np.ndarray | bool = False,
) -> np.ndarray:
    """(N, 4) float32 action for a commanded through-water heading and speed and the goal decision."""
    rel = wrap_angle(np.asarray(cmd_heading, float) - np.asarray(heading, float))
    mag = np.clip(np.asarray(cmd_speed, float) / spec.max_speed, 0.0, 1.0)
    goal = np.broadcast_to(np.where(np.asarray(home, bool), 1.0, -1.0), mag.shape)
    return np.column_stack([np.cos(rel), np.sin(rel), goal, mag]).astype(np.float32)


def action_command(spec: FeatureSpec, heading: np.ndarray, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(heading, speed) a front-seat is asked for by actions (N, 4); the goal column is not a command."""
    a = np.asarray(action, dtype=float)
    speed = np.clip(a[:, SPEED], 0.0, 1.0) * spec.max_speed
    return wrap_angle(np.asarray(heading, float) + np.arctan2(a[:, 1], a[:, 0])), speed


def predicted_current(mission: Mission, scen, obs) -> tuple[np.ndarray, np.ndarray]:
    """The tide (east, north) the back-seat predicts at this step, one value per vehicle: the report's,
    else the tide table's."""
    if obs.current_e is not None and obs.current_n is not None:
        e, n = obs.current_e, obs.current_n
    else:
        e, n = tidal_current(mission.current, scen.start_time + obs.t)
    return np.broadcast_to(e, obs.x.shape), np.broadcast_to(n, obs.x.shape)


def obstacle_view(spec: FeatureSpec, memory: ContactMemory, obs) -> np.ndarray:
    """This step's obstacle view for :func:`features`: the scan, or the contacts ``memory`` holds once it
    has folded this step's reports in (a learner's memory, or one kept beside a flying expert)."""
    if spec.observation == "scan":
        if obs.scan is None:
            raise InputError(
                "obs.scan: a scan-fed learned back-seat needs the 360-degree sonar scan (World(scan_beams=...))"
            )
        return obs.scan
    known = memory.update(obs.t, obs.contact_x, obs.contact_y, obs.detected)
    return contact_view(spec, obs.x, obs.y, obs.heading, memory.x, memory.y, known)
