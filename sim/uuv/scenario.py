"""A batch of scenarios: a mission with its parameters set from unit-cube rows.

The simulator, the autonomy and the scorer all read the same struct of arrays, one row
per scenario, so a batch of 10,000 scenarios steps with a few hundred numpy calls.  Rows
that make no sense for the range (an obstacle on the recovery point, a no-go area on a
waypoint, the launch inside a no-go area) are marked invalid with the reason; they are
reported, never simulated (section 4.4.3 pruned such scenarios too).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rapt.errors import InputError
from rapt.space import Permutation
from sim.uuv.geometry import (
    inside_rect,
    polygon_edges,
    polygon_signed_distance,
    rect_signed_distance,
    triangle_vertices,
)
from sim.uuv.mission import Mission, MissionArea, Rect

__all__ = ["Scenarios", "make_scenarios", "rects_array"]

#: A waypoint closer than this to a no-go area, or an obstacle this close to the recovery
#: point or launch, makes a scenario invalid.
CLEARANCE_M = 20.0


@dataclass
class Scenarios:
    """Per-scenario arrays (N rows); shapes in brackets.

    Rectangles are (xmin, xmax, ymin, ymax); triangles are CCW vertices.
    """

    mission: Mission
    start_time: np.ndarray  # [N] seconds after midnight
    battery0: np.ndarray  # [N] starting charge fraction
    tx_rect: np.ndarray  # [N, 4] (zeros when the mission has no transmission area)
    tx_open: np.ndarray  # [N] seconds after mission start
    tx_close: np.ndarray  # [N]
    nogo: np.ndarray  # [N, Z, 4]
    barriers: np.ndarray  # [N, B, 4]
    obstacles: np.ndarray  # [N, T, 3, 2]
    area_rect: np.ndarray  # [N, A, 4]
    area_dwell: np.ndarray  # [N, A]
    order: np.ndarray  # [N, A] area indices in priority order
    waypoints: np.ndarray  # [W, 2]
    valid: np.ndarray  # [N] bool
    invalid_reason: list[str]
    #: :attr:`obstacle_edges`' cache (recomputed when the batch size changes)
    _edges: tuple[np.ndarray, ...] | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def obstacle_edges(self) -> tuple[np.ndarray, ...]:
        """Edges of the obstacle triangles, computed once per batch (sonar reads them each step)."""
        if self._edges is None or self._edges[0].shape[0] != self.n:
            self._edges = polygon_edges(self.obstacles)
        return self._edges

    @property
    def n(self) -> int:
        return int(self.start_time.shape[0])

    def select(self, rows: np.ndarray) -> Scenarios:
        """The scenarios at ``rows`` (for simulating only the valid ones)."""
        r = np.asarray(rows)
        return Scenarios(
            self.mission,
            self.start_time[r],
            self.battery0[r],
            self.tx_rect[r],
            self.tx_open[r],
            self.tx_close[r],
            self.nogo[r],
            self.barriers[r],
            self.obstacles[r],
            self.area_rect[r],
            self.area_dwell[r],
            self.order[r],
            self.waypoints,
            self.valid[r],
            [self.invalid_reason[i] for i in np.atleast_1d(r).tolist()],
        )


def rects_array(rects, n: int) -> np.ndarray:
    """(n, K, 4) bounds of fixed rectangles, broadcast over n scenarios."""
    if not rects:
        return np.zeros((n, 0, 4))
    one = np.array([[r.x - r.width / 2, r.x + r.width / 2, r.y - r.height / 2, r.y + r.height / 2] for r in rects])
    return np.broadcast_to(one, (n, len(rects), 4)).copy()


def _set_rect_centre(arr: np.ndarray, k: int, field: str, values: np.ndarray, width: float, height: float) -> None:
    if field == "x":
        arr[:, k, 0], arr[:, k, 1] = values - width / 2, values + width / 2
    else:
        arr[:, k, 2], arr[:, k, 3] = values - height / 2, values + height / 2


def make_scenarios(mission: Mission, U: np.ndarray) -> Scenarios:
    """Decode unit-cube rows ``U`` (N, mission.dim) into a batch of scenarios."""
    U = _unit_rows(mission, U)
    n = U.shape[0]
    values = _physical_values(mission, U)

    start_time = np.full(n, float(mission.start_time_s))
    battery0 = np.full(n, float(mission.vehicle.start_battery))
    tx = mission.transmission
    tx_rect = rects_array([tx] if tx else [], n)[:, 0, :] if tx else np.zeros((n, 4))
    tx_open = np.full(n, tx.window_start_s if tx else 0.0)
    tx_len = np.full(n, tx.window_length_s if tx else 0.0)
    nogo = rects_array(mission.nogo, n)
    barriers = rects_array(mission.barriers, n)
    ob_x = np.tile([o.x for o in mission.obstacles], (n, 1)).astype(float)
    ob_y = np.tile([o.y for o in mission.obstacles], (n, 1)).astype(float)
    areas = mission.mission_areas
    area_rect = rects_array(areas, n)
    area_dwell = np.tile([a.dwell_s for a in areas], (n, 1)).astype(float)
    names = [a.name for a in areas]
    order = np.tile([names.index(p) for p in mission.priority], (n, 1)).astype(np.int64)

    # (index, element) by name, per kind; a binding of these kinds always names its element
    rect_by_name: dict[str, dict[str | None, tuple[int, Rect | MissionArea]]] = {
        "nogo": {z.name: (i, z) for i, z in enumerate(mission.nogo)},
        "barrier": {b.name: (i, b) for i, b in enumerate(mission.barriers)},
        "mission_area": {a.name: (i, a) for i, a in enumerate(areas)},
    }
    obstacle_by_name: dict[str | None, int] = {o.name: i for i, o in enumerate(mission.obstacles)}
    for b in mission.bindings:
        v = values.get(b.parameter)
        if b.kind == "mission":
            start_time = np.asarray(v, dtype=float)
        elif b.kind == "vehicle":
            battery0 = np.asarray(v, dtype=float)
        elif b.kind == "mission_areas":  # random keys -> area indices in priority order, vectorised
            order = _priority_orders(mission, b.parameter, names, U)
        elif b.kind == "transmission" and tx is not None:  # bound only when the mission has one
            if b.field in ("x", "y"):
                _set_rect_centre(tx_rect[:, None, :], 0, b.field, np.asarray(v, float), tx.width, tx.height)
            elif b.field == "window_start_s":
                tx_open = np.asarray(v, dtype=float)
            else:
                tx_len = np.asarray(v, dtype=float)
        elif b.kind in ("nogo", "barrier"):
            k, el = rect_by_name[b.kind][b.name]
            _set_rect_centre(
                nogo if b.kind == "nogo" else barriers, k, b.field, np.asarray(v, float), el.width, el.height
            )
        elif b.kind == "obstacle":
            k = obstacle_by_name[b.name]
            (ob_x if b.field == "x" else ob_y)[:, k] = np.asarray(v, dtype=float)
        elif b.kind == "mission_area":
            k, el = rect_by_name["mission_area"][b.name]
            if b.field == "dwell_s":
                area_dwell[:, k] = np.asarray(v, dtype=float)
            else:
                _set_rect_centre(area_rect, k, b.field, np.asarray(v, float), el.width, el.height)
    side = np.array([o.side for o in mission.obstacles], dtype=float)
    obstacles = triangle_vertices(ob_x, ob_y, side) if mission.obstacles else np.zeros((n, 0, 3, 2))
    waypoints = np.array(mission.waypoints, dtype=float).reshape(-1, 2)
    s = Scenarios(
        mission,
        start_time,
        battery0,
        tx_rect,
        tx_open,
        tx_open + tx_len,
        nogo,
        barriers,
        obstacles,
        area_rect,
        area_dwell,
        order,
        waypoints,
        np.ones(n, dtype=bool),
        [""] * n,
    )
    _check_validity(s)
    return s


def _unit_rows(mission: Mission, U: np.ndarray) -> np.ndarray:
    """``U`` as float rows (N, mission.dim) inside the unit cube; :class:`InputError` otherwise."""
    U = np.asarray(U, dtype=float)
    if U.ndim != 2 or U.shape[1] != mission.dim:
        raise InputError(
            f"X: expected unit-cube rows of shape (N, {mission.dim}) for mission '{mission.name}', got {U.shape}"
        )
    if U.size and (np.nanmin(U) < 0 or np.nanmax(U) > 1 or not np.all(np.isfinite(U))):
        raise InputError(
            "X: values must be finite and inside the unit cube [0, 1]; scale physical values with "
            "mission.space.to_unit_array"
        )
    return U


def _physical_values(mission: Mission, U: np.ndarray) -> dict:
    """Every row's physical value of each parameter but the permutations, by parameter name."""
    return {
        p.name: _decode(p, U[:, mission.space.slice_of(p.name)])
        for p in mission.space.parameters
        if p.kind != "permutation"
    }


def _priority_orders(mission: Mission, parameter: str, names: list[str], U: np.ndarray) -> np.ndarray:
    """(N, A) mission-area indices in priority order from the permutation ``parameter``'s random keys."""
    param = next(p for p in mission.space.parameters if isinstance(p, Permutation) and p.name == parameter)
    ranks = np.argsort(U[:, mission.space.slice_of(parameter)], axis=1, kind="stable")
    return np.array([names.index(item) for item in param.items], dtype=np.int64)[ranks]


def _decode(param, block: np.ndarray):
    """A parameter's physical values for every row (a list of tuples for permutations)."""
    return param.from_unit(block if getattr(param, "width", 1) > 1 else block[:, 0])


def _check_validity(s: Scenarios) -> None:
    """Mark scenarios the range could not run, with the first reason found."""
    m = s.mission
    reasons: list[tuple[np.ndarray, str]] = []
    for name, (px, py) in (("recovery point", m.recovery), ("launch point", m.launch)):
        x, y = np.full(s.n, float(px)), np.full(s.n, float(py))
        if s.obstacles.shape[1]:
            d, _, _ = polygon_signed_distance(x, y, s.obstacles)
            reasons.append((np.any(d < CLEARANCE_M + m.recovery_radius, axis=1), f"an obstacle on the {name}"))
        if s.barriers.shape[1]:
            d = rect_signed_distance(x, y, s.barriers)
            reasons.append((np.any(d < CLEARANCE_M + m.recovery_radius, axis=1), f"a barrier on the {name}"))
        if s.nogo.shape[1]:
            d = rect_signed_distance(x, y, s.nogo)
            reasons.append((np.any(d < CLEARANCE_M + m.recovery_radius, axis=1), f"a no-go area on the {name}"))
    for w, (wx, wy) in enumerate(s.waypoints):
        x, y = np.full(s.n, wx), np.full(s.n, wy)
        if s.nogo.shape[1]:
            reasons.append((np.any(inside_rect(x, y, s.nogo), axis=1), f"a no-go area on waypoint {w}"))
        if s.obstacles.shape[1]:
            d, _, _ = polygon_signed_distance(x, y, s.obstacles)
            reasons.append((np.any(d < CLEARANCE_M, axis=1), f"an obstacle on waypoint {w}"))
        if s.barriers.shape[1]:
            reasons.append((np.any(inside_rect(x, y, s.barriers), axis=1), f"a barrier on waypoint {w}"))
    if s.nogo.shape[1] and s.area_rect.shape[1]:
        cx = (s.area_rect[..., 0] + s.area_rect[..., 1]) / 2
        cy = (s.area_rect[..., 2] + s.area_rect[..., 3]) / 2
        for a in range(s.area_rect.shape[1]):
            reasons.append(
                (
                    np.any(inside_rect(cx[:, a], cy[:, a], s.nogo), axis=1),
                    f"a no-go area on the centre of mission area {m.mission_areas[a].name}",
                )
            )
    for bad, why in reasons:
        new = bad & s.valid
        for i in np.flatnonzero(new):
            s.invalid_reason[i] = why
        s.valid &= ~bad
