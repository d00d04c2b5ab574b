"""Vehicle terms fitted to segment replays, and which speed loop the segments say the vehicle has.

:func:`planner.review.vehicle_fit.fit_vehicle` fits a vehicle block to logs by replaying their
open-loop segments (:mod:`planner.review.segments`) under trial values and comparing the
predicted positions, headings and energy with the logged ones.  :class:`SegmentSolver` is that
fit for one set of segments; :func:`choose_loop` fits both speed loops a vehicle may have (a
torpedo's, driving the speed along its bow; a thruster vehicle's vector loop, driving an
earth-frame velocity with a slow part) and keeps the one the positions bear out.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Mapping, Sequence
from types import SimpleNamespace

import numpy as np

from planner.review.calibration_legs import empty_estimate, merged
from planner.review.calibration_terms import with_terms
from planner.review.segments import Segments, replay
from rapt.mapfit import MapEstimate, Prior, fit_map
from sim.uuv.angles import wrap_angle
from sim.uuv.bias import BIAS_NAMES, Bias
from sim.uuv.mission import Mission, Vehicle

__all__ = [
    "SegmentSolver",
    "choose_loop",
    "residual_parts",
    "rms_of",
    "SIGMA_POSITION_M",
    "SIGMA_HEADING_DEG",
    "SIGMA_ENERGY_WH",
    "TURN_TERMS",
    "SLOW_TERMS",
    "CONTROL_MARGIN",
    "TURN_GRID",
]

#: Residual units: metres of position, degrees of heading, watt-hours of energy used.
SIGMA_POSITION_M = 1.0
SIGMA_HEADING_DEG = 2.0
SIGMA_ENERGY_WH = 0.05
#: The terms that shape the heading alone when the speed loop is a vector one.
TURN_TERMS = ("max_turn_rate_dps", "yaw_time_constant_s", "heading_time_s")
#: The terms of a vector speed loop's slow part: fitted only when the logs choose that loop.
SLOW_TERMS = ("slow_share", "slow_time_constant_s")
#: Where the turn terms' fit to the headings may start, as shares of the file's values: a thruster vehicle
#: turns several times faster than a torpedo and closes a heading error in a fraction of its time.  Every
#: point is replayed (in one batch) and the fit starts from the one whose headings fit best.
TURN_GRID = {
    "max_turn_rate_dps": (0.5, 1.0, 2.0, 4.0),
    "yaw_time_constant_s": (0.05, 0.15, 0.5, 1.0),
    "heading_time_s": (0.05, 0.15, 0.5, 1.0),
}
#: The vector loop is chosen when its segment position residual is at least this share below the surge loop's.
CONTROL_MARGIN = 0.1


def residual_parts(
    mission: Mission, seg: Segments, vehicle: Vehicle, water: Bias | None = None
) -> tuple[np.ndarray, ...]:
    """Position (m, east and north), heading (deg) and energy (Wh) errors of every valid segment step."""
    px, py, pe, ph = replay(mission, seg, water, vehicle=vehicle)
    v = seg.valid
    dh = np.rad2deg(wrap_angle(ph - seg.obs_heading))
    return (px - seg.obs_x)[v], (py - seg.obs_y)[v], dh[v], (pe - seg.obs_energy_wh)[v]


def stacked_trials(trials: Sequence[tuple[Vehicle, Bias]], n: int) -> tuple[SimpleNamespace, SimpleNamespace | Bias]:
    """Trial vehicles and waters as one vehicle and one water for a replay of ``n`` segments repeated once
    per trial (:meth:`planner.review.segments.Segments.repeated`): a field the trials share stays as it is,
    one they differ in becomes a value per segment, and differing speed curves an (N, K, 2) array."""
    vehicles = [v for v, _ in trials]
    first = vehicles[0]
    fields = {}
    for f in dataclasses.fields(first):
        values = [getattr(v, f.name) for v in vehicles]
        if all(x == values[0] for x in values[1:]):
            fields[f.name] = values[0]
        elif f.name == "speed_curve":
            curves = np.array(values, dtype=float)  # (p, K, 2): the knots' commands are the fit's, shared
            fields[f.name] = np.repeat(curves, n, axis=0)
        else:
            fields[f.name] = np.repeat(np.array(values, dtype=float), n)
    waters = [w for _, w in trials]
    if all(w == waters[0] for w in waters[1:]):
        return SimpleNamespace(**fields), waters[0]
    water = SimpleNamespace(**{b: np.repeat(np.array([getattr(w, b) for w in waters]), n) for b in BIAS_NAMES})
    return SimpleNamespace(**fields), water


def rms_of(parts: tuple[np.ndarray, ...]) -> dict[str, float]:
    dx, dy, dh, de = parts
    return {
        "position_m": float(np.sqrt(np.mean(dx**2 + dy**2))),
        "heading_deg": float(np.sqrt(np.mean(dh**2))),
        "energy_wh": float(np.sqrt(np.mean(de**2))),
    }


class SegmentSolver:
    """MAP fits of vehicle terms to one set of segments (``priors`` gives each term's prior;
    ``blocks`` labels each valid step's bootstrap block; ``seed`` seeds the bootstrap)."""

    def __init__(
        self,
        mission: Mission,
        seg: Segments,
        priors: Callable[[Vehicle, Sequence[str]], list[Prior]],
        blocks: np.ndarray,
        seed: int = 0,
        turn_known: Mapping[str, float] | None = None,
    ):
        self.mission, self.seg, self.priors, self.blocks, self.seed = mission, seg, priors, blocks, seed
        self.turn_known = dict(turn_known or {})  # an earlier calibration's turn of this vehicle
        self._tiled: dict[int, Segments] = {}  # the segments repeated p times, per trial count p
        self._turn_found: dict[tuple, dict[str, float]] = {}  # turn_start's optimum per (terms, vehicle)

    def solve_kinds(
        self,
        names: tuple[str, ...],
        vehicle: Vehicle,
        bootstrap: int,
        start,
        used: tuple[str, ...],
        robust: bool = True,
        departed: bool = False,
    ) -> MapEstimate:
        """The MAP fit of ``names`` to the residual kinds ``used`` (of position, heading, energy);
        ``departed`` as :func:`rapt.mapfit.fit_map`'s."""
        mission, seg = self.mission, self.seg

        def residuals(theta: np.ndarray) -> np.ndarray:
            dx, dy, dh, de = residual_parts(mission, seg, *with_terms(vehicle, dict(zip(names, theta))))
            parts = {
                "position": (dx / SIGMA_POSITION_M, dy / SIGMA_POSITION_M),
                "heading": (dh / SIGMA_HEADING_DEG,),
                "energy": (de / SIGMA_ENERGY_WH,),
            }
            return np.concatenate([r for k in used for r in parts[k]])

        def residuals_many(thetas: np.ndarray) -> np.ndarray:
            """Every trial's residuals from one replay of the segments repeated once per trial."""
            dx, dy, dh, de = self.trial_parts(vehicle, [dict(zip(names, th)) for th in thetas])
            parts = {
                "position": (dx / SIGMA_POSITION_M, dy / SIGMA_POSITION_M),
                "heading": (dh / SIGMA_HEADING_DEG,),
                "energy": (de / SIGMA_ENERGY_WH,),
            }
            return np.concatenate([r for k in used for r in parts[k]], axis=1)

        if not names:
            return empty_estimate()
        width = {"position": 2, "heading": 1, "energy": 1}
        kinds = np.repeat(np.array([k for k in used for _ in range(width[k])]), self.blocks.size)
        groups = np.concatenate([self.blocks] * sum(width[k] for k in used))
        kw = {"groups": groups, "kinds": kinds, "bootstrap": bootstrap, "seed": self.seed, "start": start}
        kw["residuals_many"] = residuals_many
        return fit_map(residuals, self.priors(vehicle, names), significant=0.0, robust=robust, departed=departed, **kw)

    def trial_parts(self, vehicle: Vehicle, trials: Sequence[dict[str, float]]) -> tuple[np.ndarray, ...]:
        """:func:`residual_parts` of ``vehicle`` under each of ``trials`` (name -> value), as (trials, steps)
        arrays, from one replay of the segments repeated once per trial."""
        p, n = len(trials), self.seg.valid.shape[0]
        tiled = self._tiled.get(p)
        if tiled is None:
            tiled = self._tiled[p] = self.seg.repeated(p)
        spec, water = stacked_trials([with_terms(vehicle, t) for t in trials], n)
        # the stacked trials carry the Vehicle's and Bias's fields as per-segment arrays
        batched = residual_parts(self.mission, tiled, spec, water)  # type: ignore[arg-type]
        return tuple(r.reshape(p, -1) for r in batched)

    def solve(self, names: tuple[str, ...], vehicle: Vehicle, bootstrap: int, start=None) -> MapEstimate:
        """The MAP fit of ``names``.  A vector loop's track does not depend on its heading, so its
        turn terms are fitted to the headings alone and the rest to positions and energy: the same
        optimum, found as two well-scaled problems instead of one whose heading part is lost."""
        if vehicle.velocity_control != "vector" or not set(TURN_TERMS) & set(names):
            return self.solve_kinds(names, vehicle, bootstrap, start, ("position", "heading", "energy"))
        turn = tuple(n for n in names if n in TURN_TERMS)
        rest = tuple(n for n in names if n not in TURN_TERMS)
        a = self.solve_kinds(rest, vehicle, bootstrap, start, ("position", "energy"))
        # a heading moves only in turns: its information is in the few large residuals a robust fit discards
        # a torpedo's file is no yardstick for a thruster's turn: the headings identify what they move far
        b = self.solve_kinds(
            turn, vehicle, bootstrap, self.turn_start(turn, vehicle, start), ("heading",), robust=False, departed=True
        )
        return merged(a, b) if rest else b

    def turn_start(self, turn: tuple[str, ...], vehicle: Vehicle, start) -> dict:
        """Where the turn terms' fit to the headings starts: from ``start``, from the file's values or from
        the best point of :data:`TURN_GRID`, whichever optimum leaves the lowest heading residual.

        Fitted to the headings alone a log can hold several optima, the turn rate against the yaw lag and
        the heading time trading off, and a vehicle that turns unlike its file lies many prior widths
        from it: from the file's values, or from where the loop's fit ended, the fit may stall on a
        ridge where the terms confound each other and none is identified.  The grid's points are replayed
        in one batch; each origin's optimum is found without the bootstrap; the full fit starts at the best.

        A vector loop's headings do not move with its speed terms, so the optimum found for the loop's
        choice is where the final fit of the same vehicle starts too, not searched for again.  Where an
        earlier calibration of the vehicle found its turn (``turn_known``: the day's water added to it), the
        fit starts there alone: the water does not change how the vehicle turns.
        """
        start = dict(start or {})
        key = (turn, vehicle)
        if key not in self._turn_found and all(n in self.turn_known for n in turn):
            est = self.solve_kinds(turn, vehicle, 0, {**start, **self.turn_known}, ("heading",), robust=False)
            self._turn_found[key] = {n: float(est.map_value[n]) for n in est.names}
        if key in self._turn_found:
            return {**start, **self._turn_found[key]}
        bounds = {p.name: (p.low, p.high) for p in self.priors(vehicle, turn)}
        base = {n: float(start.get(n, getattr(vehicle, n))) for n in turn}
        grid = [
            {n: float(np.clip(getattr(vehicle, n) * share, *bounds[n])) for n, share in zip(turn, shares)}
            for shares in itertools.product(*(TURN_GRID[n] for n in turn))
        ]
        heading = self.trial_parts(vehicle, [{**start, **point} for point in grid])[2]
        file = {n: float(getattr(vehicle, n)) for n in turn}
        origins = [base, file, grid[int(np.argmin(np.mean(heading**2, axis=1)))]]
        origins = [o for i, o in enumerate(origins) if o not in origins[:i]]
        found = []
        for origin in origins:
            est = self.solve_kinds(turn, vehicle, 0, {**start, **origin}, ("heading",), robust=False)
            values = {n: float(est.map_value[n]) for n in est.names}
            found.append((self.heading_rms(vehicle, {**start, **values}), values))
        self._turn_found[key] = min(found, key=lambda f: f[0])[1]
        return {**start, **self._turn_found[key]}

    def heading_rms(self, vehicle: Vehicle, values: dict[str, float]) -> float:
        """The segments' heading residual RMS (deg) of ``vehicle`` with ``values``."""
        return rms_of(residual_parts(self.mission, self.seg, *with_terms(vehicle, values)))["heading_deg"]


def choose_loop(
    mission: Mission,
    seg: Segments,
    names: tuple[str, ...],
    slow: tuple[str, ...],
    base: Vehicle,
    solve,
    start: dict[str, float],
    known: str | None = None,
) -> tuple[Vehicle, tuple[str, ...], dict, dict[str, float]]:
    """The speed loop the segments say the vehicle has, the names to fit with it, the account, and
    where its fit ended (the full fit starts there).

    Both loops are fitted to the segments (without the bootstrap): the surge loop with
    ``names``, the vector loop with its slow part (``slow``) as well.  The vector loop is
    taken when its position residual RMS is at least :data:`CONTROL_MARGIN` below the surge
    loop's; otherwise the simpler surge loop stands.  No ``slow`` terms asked for: the
    file's loop, unexamined.  A ``known`` loop (an earlier calibration's choice on the same
    vehicle) is kept without fitting the other: the fit starts from ``start``.
    """
    if not slow:
        return base, names, {}, start
    if known is not None:
        account: dict = {"chosen": known, "file": base.velocity_control, "kept": "chosen by the calibration compared"}
        return (
            dataclasses.replace(base, velocity_control=known),
            names + slow if known == "vector" else names,
            account,
            start,
        )
    rms: dict[str, float] = {}
    found: dict[str, dict[str, float]] = {}
    for control, fitted in (("surge", names), ("vector", names + slow)):
        vehicle = dataclasses.replace(base, velocity_control=control)
        est = solve(fitted, vehicle, 0, start)
        found[control] = {n: float(est.map_value[n]) for n in est.names}
        trial = with_terms(vehicle, found[control])  # each loop at its best, every term free
        rms[control] = rms_of(residual_parts(mission, seg, *trial))["position_m"]
    chosen = "vector" if rms["vector"] < (1.0 - CONTROL_MARGIN) * rms["surge"] else "surge"
    account = {"chosen": chosen, "file": base.velocity_control, "position_rms_m": rms}
    fitted = names + slow if chosen == "vector" else names
    return dataclasses.replace(base, velocity_control=chosen), fitted, account, found[chosen]
