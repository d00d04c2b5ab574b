"""Hierarchical scoring of a run from the vehicle's true track (Figure 4.11, Table 3.2).

The scorer watches ground truth, never the autonomy's beliefs: a vehicle that thinks it
loitered inside a mission area but drifted out did not survey it.  It is fed one step at
a time — by the batch simulator here, or by the software-in-the-loop logger with the
front-seat's telemetry — and returns the columns of :func:`sim.uuv.metrics.metric_names`.

Rules (Table 3.2): waypoints are recommended, not required; every mission area must be
surveyed for its dwell time, in priority order; data must be sent from the surface inside
the transmission area while its window is open; surfacing anywhere else (except at the
recovery point) is a safety failure; touching an obstacle or leaving the operational area
is a safety failure that ends the run; entering a no-go area is a safety failure but the
run goes on; not reaching the recovery point is a safety failure.
"""

from __future__ import annotations

import numpy as np

from sim.uuv.geometry import rect_signed_distance
from sim.uuv.metrics import NEVER_M, metric_names
from sim.uuv.scenario import Scenarios

__all__ = ["Scorer", "MODE_NAMES", "mode_name", "modes_from_scores"]

#: Performance modes (section 3.7.1): code = 2 * mission success + safety success.
MODE_NAMES = ("TF", "SS", "MS", "TS")


def mode_name(scores: np.ndarray) -> str:
    """The performance mode of one run's (finite) scores: ``TF``, ``SS``, ``MS`` or ``TS``."""
    return MODE_NAMES[int(2 * scores[0] + scores[1])]


def modes_from_scores(scores: np.ndarray) -> np.ndarray:
    """Mode code of each row from the two root columns; -1 where the row is NaN (invalid)."""
    ok = np.isfinite(scores[:, 0]) & np.isfinite(scores[:, 1])
    return np.where(ok, 2 * np.nan_to_num(scores[:, 0]).astype(int) + np.nan_to_num(scores[:, 1]).astype(int), -1)


class Scorer:
    """Accumulates every metric of N runs; :meth:`scores` gives the (N, m) matrix."""

    def __init__(self, scen: Scenarios):
        m = scen.mission
        self.scen, self.mission = scen, m
        n, W, A = scen.n, scen.waypoints.shape[0], scen.area_rect.shape[1]
        T, B, Z = scen.obstacles.shape[1], scen.barriers.shape[1], scen.nogo.shape[1]
        limit = m.time_limit_s
        self.limit = limit
        self.wp_closest = np.full((n, W), NEVER_M)
        self.wp_time = np.full((n, W), limit)
        self.wp_battery = np.zeros((n, W))
        self.area_dwell = np.zeros((n, A))
        self.area_entry = np.full((n, A), limit)
        self.area_done = np.full((n, A), limit)
        self.area_closest = np.full((n, A), NEVER_M)
        self.area_rank = np.zeros((n, A))
        self.n_done = np.zeros(n)
        self.tx_accum = np.zeros(n)
        self.tx_time = np.full(n, limit)
        self.tx_closest = np.full(n, NEVER_M)
        self.tx_surface = np.zeros(n)
        self.ob_closest = np.full((n, T + B), NEVER_M)
        self.ob_time = np.full((n, T + B), limit)
        self.ob_detected = np.full((n, T + B), limit)
        self.ng_closest = np.full((n, Z), NEVER_M)
        self.ng_inside = np.zeros((n, Z))
        self.ng_time = np.full((n, Z), limit)
        self.op_margin = np.full(n, NEVER_M)
        self.rec_distance = np.full(n, NEVER_M)
        self.rec_time = np.full(n, limit)
        self.rec_battery = np.zeros(n)
        self.surf_outside = np.zeros(n)
        self.surf_count = np.zeros(n)
        self.was_surfaced_outside = np.zeros(n, dtype=bool)
        self.distance = np.zeros(n)
        self.end_time = np.full(n, limit)
        self.battery_left = scen.battery0.copy()
        self.recovered = np.zeros(n, dtype=bool)
        self.collided = np.zeros(n, dtype=bool)
        self.left_area = np.zeros(n, dtype=bool)
        op = m.operational_area
        self.op_bounds = (op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2)
        rx, ry = m.launch
        self.prev_x, self.prev_y = np.full(n, float(rx)), np.full(n, float(ry))
        self._rows = np.arange(n)

    def update_from(self, tel, active: np.ndarray, nogo_distance: np.ndarray | None = None) -> np.ndarray:
        """Score one step of telemetry (:class:`sim.uuv.world.Telemetry`); returns the runs that end here."""
        step_m = np.hypot(tel.x - self.prev_x, tel.y - self.prev_y)
        self.prev_x, self.prev_y = tel.x, tel.y
        return self.update(
            tel.t,
            tel.x,
            tel.y,
            tel.battery,
            tel.surfaced,
            tel.contact_distance,
            tel.detected,
            step_m,
            active,
            nogo_distance,
        )

    def update(
        self,
        t: float,
        x: np.ndarray,
        y: np.ndarray,
        battery: np.ndarray,
        surfaced: np.ndarray,
        contacts_distance: np.ndarray,
        detected: np.ndarray,
        step_m: np.ndarray,
        active: np.ndarray,
        nogo_distance: np.ndarray | None = None,
    ) -> np.ndarray:
        """Score one step of the ``active`` runs; returns the runs that end here.

        A run ends when the vehicle surfaces at the recovery point (recovered), touches an
        obstacle, leaves the operational area or runs out of battery.
        """
        scen, m, a = self.scen, self.mission, active
        self.distance += np.where(a, step_m, 0.0)
        self.battery_left = np.where(a, battery, self.battery_left)
        W = scen.waypoints.shape[0]
        if W:
            d = np.hypot(scen.waypoints[None, :, 0] - x[:, None], scen.waypoints[None, :, 1] - y[:, None])
            d = np.where(a[:, None], d, NEVER_M)
            self.wp_closest = np.minimum(self.wp_closest, d)
            first = (d <= m.waypoint_radius) & (self.wp_time >= self.limit)
            self.wp_time = np.where(first, t, self.wp_time)
            self.wp_battery = np.where(first, battery[:, None], self.wp_battery)
        A = scen.area_rect.shape[1]
        if A:
            d = np.where(a[:, None], rect_signed_distance(x, y, scen.area_rect), NEVER_M)
            self.area_closest = np.minimum(self.area_closest, d)
            inside = d <= 0
            self.area_entry = np.where(inside & (self.area_entry >= self.limit), t, self.area_entry)
            self.area_dwell += np.where(inside, m.dt, 0.0)
            done = inside & (self.area_dwell >= scen.area_dwell) & (self.area_done >= self.limit)
            if np.any(done):
                self.area_done = np.where(done, t, self.area_done)
                for k in range(A):  # rank of completion, 1 = first
                    self.n_done += done[:, k]
                    self.area_rank[:, k] = np.where(done[:, k], self.n_done, self.area_rank[:, k])
        if m.transmission is not None:
            d = np.where(a, rect_signed_distance(x, y, scen.tx_rect[:, None, :])[:, 0], NEVER_M)
            self.tx_closest = np.minimum(self.tx_closest, d)
            window = (t >= scen.tx_open) & (t < scen.tx_close)
            sending = surfaced & a & (d <= 0) & window
            self.tx_surface += np.where(surfaced & a & (d <= 0), m.dt, 0.0)
            self.tx_accum += np.where(sending, m.dt, 0.0)
            sent = (self.tx_accum >= m.transmission.duration_s) & (self.tx_time >= self.limit)
            self.tx_time = np.where(sent, t, self.tx_time)
            allowed = sending
        else:
            allowed = np.zeros_like(surfaced)
        rx, ry = m.recovery
        rec_d = np.hypot(x - rx, y - ry)
        at_recovery = rec_d <= m.recovery_radius
        outside = surfaced & a & ~allowed & ~at_recovery
        self.surf_outside += np.where(outside, m.dt, 0.0)
        self.surf_count += outside & ~self.was_surfaced_outside
        self.was_surfaced_outside = outside

        if contacts_distance.shape[1]:
            d = np.where(a[:, None], contacts_distance, NEVER_M)
            closer = d < self.ob_closest
            self.ob_closest = np.where(closer, d, self.ob_closest)
            self.ob_time = np.where(closer, t, self.ob_time)
            self.ob_detected = np.where(detected & a[:, None] & (self.ob_detected >= self.limit), t, self.ob_detected)
            hit = a & np.any(d <= 0, axis=1)
        else:
            hit = np.zeros_like(a)
        if scen.nogo.shape[1]:
            d = rect_signed_distance(x, y, scen.nogo) if nogo_distance is None else nogo_distance
            d = np.where(a[:, None], d, NEVER_M)
            self.ng_closest = np.minimum(self.ng_closest, d)
            self.ng_inside += np.where(d <= 0, m.dt, 0.0)
            self.ng_time = np.where((d <= 0) & (self.ng_time >= self.limit), t, self.ng_time)
        op = self.op_bounds  # inside margin; negative once outside (the run ends there)
        op_d = np.minimum(np.minimum(x - op[0], op[1] - x), np.minimum(y - op[2], op[3] - y))
        self.op_margin = np.where(a, np.minimum(self.op_margin, op_d), self.op_margin)
        left = a & (op_d < 0)
        self.rec_distance = np.where(a, np.minimum(self.rec_distance, rec_d), self.rec_distance)
        home = a & surfaced & at_recovery
        self.rec_time = np.where(home, t, self.rec_time)
        self.rec_battery = np.where(home, battery, self.rec_battery)
        dead = a & (battery <= 0)
        self.recovered |= home
        self.collided |= hit
        self.left_area |= left
        ended = home | hit | left | dead
        self.end_time = np.where(ended, t, self.end_time)
        return ended

    def end_reason(self, row: int = 0) -> str:
        """Why run ``row`` ended, in the front-seat's words (its last :meth:`update` said it ended)."""
        if self.recovered[row]:
            return "recovered"
        if self.collided[row]:
            return "collision"
        if self.left_area[row]:
            return "left the operational area"
        return "battery empty"

    def scores(self, wp_aborted: np.ndarray, return_reason: np.ndarray) -> np.ndarray:
        """The (N, m) score matrix in :func:`sim.uuv.metrics.metric_names` order.

        Two leaves are the autonomy's own decisions, which no track shows: which waypoints it
        abandoned and why it turned home (the back-seat reports them on its status channel).
        """
        scen, m = self.scen, self.mission
        n = scen.n
        W, A = scen.waypoints.shape[0], scen.area_rect.shape[1]
        T, B = scen.obstacles.shape[1], scen.barriers.shape[1]
        wp_ok = self.wp_time < self.limit
        area_ok = self.area_done < self.limit
        if A:  # in priority order: each area done no later than the next in the order
            done_in_order = np.take_along_axis(self.area_done, scen.order, axis=1)
            ordered = np.all(np.diff(done_in_order, axis=1) >= 0, axis=1) if A > 1 else np.ones(n, bool)
            areas_pass = np.all(area_ok, axis=1) & ordered
        else:
            areas_pass = np.ones(n, dtype=bool)
        tx_pass = self.tx_time < self.limit if m.transmission is not None else np.ones(n, dtype=bool)
        time_pass = self.recovered & (self.rec_time < self.limit)
        nodes = {
            "waypoints": np.all(wp_ok, axis=1) if W else np.ones(n, bool),
            "mission_areas": areas_pass,
            "transmission": tx_pass,
            "mission_time": time_pass,
        }
        ob_ok = self.ob_closest > 0
        ng_ok = self.ng_inside <= 0
        safety = {
            "collisions": np.all(ob_ok, axis=1),
            "nogo_areas": np.all(ng_ok, axis=1),
            "operational_area": ~self.left_area,
            "recovery": self.recovered,
            "surfacing": self.surf_outside <= 0,
        }
        mission_ok = np.all([nodes[r] for r in m.mission_requires], axis=0) if m.mission_requires else np.ones(n, bool)
        safety_ok = np.all(list(safety.values()), axis=0)

        cols: dict[str, np.ndarray] = {"mission_success": mission_ok, "safety_success": safety_ok}
        cols.update(nodes)
        cols.update(safety)
        for i in range(W):
            cols[f"waypoint.{i}"] = wp_ok[:, i]
            cols[f"waypoint.{i}.closest_m"] = self.wp_closest[:, i]
            cols[f"waypoint.{i}.time_s"] = self.wp_time[:, i]
            cols[f"waypoint.{i}.battery"] = self.wp_battery[:, i]
            cols[f"waypoint.{i}.aborted"] = wp_aborted[:, i]
        for k, area in enumerate(m.mission_areas):
            cols[f"area.{area.name}"] = area_ok[:, k]
            for leaf, arr in (
                ("dwell_s", self.area_dwell),
                ("entry_s", self.area_entry),
                ("done_s", self.area_done),
                ("closest_m", self.area_closest),
                ("order", self.area_rank),
            ):
                cols[f"area.{area.name}.{leaf}"] = arr[:, k]
        if m.transmission is not None:
            cols["transmission.time_s"] = self.tx_time
            cols["transmission.window_margin_s"] = np.where(tx_pass, scen.tx_close - self.tx_time, -self.limit)
            cols["transmission.closest_m"] = self.tx_closest
            cols["transmission.surface_s"] = self.tx_surface
        cols["mission.time_s"] = self.end_time
        cols["mission.battery_left"] = self.battery_left
        cols["mission.distance_m"] = self.distance
        cols["mission.return_reason"] = return_reason
        names = [o.name for o in m.obstacles] + [b.name for b in m.barriers]
        kinds = ["obstacle"] * T + ["barrier"] * B
        for k, (kind, name) in enumerate(zip(kinds, names)):
            cols[f"{kind}.{name}"] = ob_ok[:, k]
            cols[f"{kind}.{name}.closest_m"] = self.ob_closest[:, k]
            cols[f"{kind}.{name}.time_s"] = self.ob_time[:, k]
            cols[f"{kind}.{name}.detected_s"] = self.ob_detected[:, k]
        for k, z in enumerate(m.nogo):
            cols[f"nogo.{z.name}"] = ng_ok[:, k]
            cols[f"nogo.{z.name}.closest_m"] = self.ng_closest[:, k]
            cols[f"nogo.{z.name}.inside_s"] = self.ng_inside[:, k]
            cols[f"nogo.{z.name}.time_s"] = self.ng_time[:, k]
        cols["operational_area.margin_m"] = self.op_margin
        cols["recovery.distance_m"] = self.rec_distance
        cols["recovery.time_s"] = self.rec_time
        cols["recovery.battery"] = self.rec_battery
        cols["surfacing.outside_s"] = self.surf_outside
        cols["surfacing.count"] = self.surf_count
        return np.column_stack([np.asarray(cols[name], dtype=float) for name in metric_names(m)])
