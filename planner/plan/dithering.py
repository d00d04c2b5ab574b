"""Dithering studies (sections 4.4.5-4.4.7) and robust variants (section 4.5.3's "M" scenarios).

A plan scenario will not run on the water exactly as planned. The vehicle's navigation
is off by metres, the run starts a minute late, and the battery gauge reads a percent
high. :class:`DitherNoise` states that expected execution noise in the mission's own
units and turns it into a Gaussian sigma per unit-cube coordinate. :func:`dither_many`
re-simulates each scenario under that noise with the stochastic effects on. It then
measures how often the scenario still shows what the plan predicts for it: its mode,
and the values of its pair's score elements.

:func:`robust_variants` moves a fragile scenario, one that shows its prediction less
often than the plan needs, away from its boundary. It tries three directions: away from
the pair's other scenario, up the dithers' own gradient (from the runs that missed
towards the runs that held), and along the most sensitive parameters. It keeps the
smallest move whose dithers hold the prediction often enough. The 2017 team made such
variants by hand.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import sim.uuv
from planner.common.execution_noise import NOISE_KINDS, dithered_runs, noise_kind
from rapt.errors import InputError
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = [
    "DitherNoise",
    "DEFAULT_NOISE",
    "MAX_SIGMA_SHARE",
    "Outcome",
    "outcome_columns",
    "dither_many",
    "dither_stats",
    "robust_variants",
    "VARIANT_STEPS",
]

#: What a small AUV's range day is expected to miss by: navigation error (metres) on every
#: position, start and timing slip (seconds) on every time, battery gauge error (percent
#: of capacity) on the starting charge. A priority order is the plan's choice, not noise.
DEFAULT_NOISE = "position=10,time=30,battery=1"
#: A sigma above this share of a parameter's range blurs the whole range: an input error.
MAX_SIGMA_SHARE = 0.25


@dataclass(frozen=True)
class DitherNoise:
    """Expected execution noise: a unit-cube sigma, or per kind of parameter in physical units.

    ``--dither-sigma 0.02`` dithers every coordinate by 0.02 of its range.
    ``--dither-sigma position=10,time=30,battery=1`` dithers each parameter by the noise
    of its kind: metres for positions, seconds for times, percent of capacity for the
    starting battery. Kinds left out keep :data:`DEFAULT_NOISE`'s values.
    """

    unit: float | None = None
    position_m: float = 10.0
    time_s: float = 30.0
    battery_pct: float = 1.0

    @classmethod
    def parse(cls, spec: str | float) -> DitherNoise:
        """From the ``--dither-sigma`` text; a one-line :class:`InputError` naming the fix otherwise."""
        if isinstance(spec, (int, float)) and not isinstance(spec, bool):
            return cls._unit(float(spec))
        text = str(spec).strip()
        try:
            unit = float(text)
        except ValueError:
            unit = None
        if unit is not None:
            return cls._unit(unit)
        values: dict[str, float] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            m = re.fullmatch(r"(position|time|battery)\s*=\s*([0-9.eE+-]+)\s*(m|s|%)?", part)
            if m is None or (m.group(3) and m.group(3) != NOISE_KINDS[m.group(1)]):
                raise InputError(
                    f"--dither-sigma: cannot read {part!r}; expected a unit-cube sigma such as 0.02 or "
                    "kind=value pairs such as position=10,time=30,battery=1 (metres, seconds, percent)"
                )
            try:
                value = float(m.group(2))
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"--dither-sigma: {m.group(1)} must be a positive number, got {m.group(2)!r}")
            values[m.group(1)] = value
        if not values:
            raise InputError("--dither-sigma: expected 0.02 or position=10,time=30,battery=1, got nothing")
        default = cls()
        return cls(
            None,
            values.get("position", default.position_m),
            values.get("time", default.time_s),
            values.get("battery", default.battery_pct),
        )

    @classmethod
    def _unit(cls, sigma: float) -> DitherNoise:
        if not (math.isfinite(sigma) and 0 < sigma <= MAX_SIGMA_SHARE):
            raise InputError(
                f"--dither-sigma: a unit-cube sigma must be in (0, {MAX_SIGMA_SHARE}], got {sigma}; "
                "or give the noise in physical units: position=10,time=30,battery=1"
            )
        return cls(unit=sigma)

    def sigmas(self, mission: Mission) -> np.ndarray:
        """The Gaussian sigma of each unit-cube coordinate of ``mission``'s study space."""
        space = mission.space
        out = np.zeros(space.dim)
        for binding in mission.bindings:
            param = next(p for p in space.parameters if p.name == binding.parameter)
            cols = space.slice_of(param.name)
            if self.unit is not None:
                out[cols] = 0.0 if param.kind == "permutation" else self.unit
                continue
            kind = noise_kind(binding.field)
            if kind is None or param.kind != "continuous":
                continue
            physical = {"position": self.position_m, "time": self.time_s, "battery": self.battery_pct / 100.0}[kind]
            share = physical / (float(param.high) - float(param.low))  # type: ignore[union-attr]
            if share > MAX_SIGMA_SHARE:
                raise InputError(
                    f"--dither-sigma: {kind}={self.as_dict()[kind]} is {share:.2f} of {param.name}'s range; "
                    f"expected at most {MAX_SIGMA_SHARE} of it (lower {kind})"
                )
            out[cols] = share
        return out

    def as_dict(self) -> dict[str, float]:
        if self.unit is not None:
            return {"unit": self.unit}
        return {"position": self.position_m, "time": self.time_s, "battery": self.battery_pct}

    def describe(self) -> str:
        if self.unit is not None:
            return f"{self.unit:g} of each parameter's range"
        return f"position {self.position_m:g} m, time {self.time_s:g} s, battery {self.battery_pct:g} %"


def outcome_columns(root: list[int], names: list[str], elements: list[str]) -> list[int]:
    """Score columns that make up a pair's outcome: the root scores, then the pair's elements."""
    return list(root) + [c for c in (names.index(e) for e in elements) if c not in root]


@dataclass(frozen=True)
class Outcome:
    """What the plan predicts a scenario shows: its mode, and its pair's element values.

    ``columns`` are score columns (the root scores and the pair's elements) and ``values``
    the scenario's values on them; a run shows the outcome when it is valid and matches on
    every column.
    """

    mode: int
    columns: tuple[int, ...]
    values: tuple[float, ...]

    def shown(self, scores: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Which runs (rows of ``scores``, with their validity) show the outcome."""
        cols = list(self.columns)
        return valid & np.all(scores[:, cols] == np.asarray(self.values), axis=1)


# -- dithering --------------------------------------------------------------------------------
def dither_many(
    mission: Mission,
    centres: np.ndarray,
    outcomes: Sequence[Outcome],
    elements: Sequence[list[str]],
    n: int,
    sigma: np.ndarray,
    seed: int,
    surrogate=None,
) -> tuple[list[dict], np.ndarray, np.ndarray, np.ndarray]:
    """Stochastic runs of ``n`` Gaussian dithers around each centre, all in one batch.

    ``sigma`` is the per-coordinate sigma (:meth:`DitherNoise.sigmas`). Returns, per
    centre, the statistics of :func:`dither_stats`, and for the report the dithers'
    unit-cube rows and modes, shaped (k, n, d) and (k, n). The first dither of each
    centre is the centre itself, run with the stochastic effects on.
    """
    centres = np.atleast_2d(np.asarray(centres, dtype=float))
    k = centres.shape[0]
    U, r = _dithered(mission, centres, n, sigma, seed, surrogate)
    stats = []
    shown = np.zeros((k, n), dtype=bool)
    for c in range(k):
        rows = slice(c * n, (c + 1) * n)
        shown[c] = outcomes[c].shown(r.scores[rows], r.valid[rows])
        stats.append(
            dither_stats(
                U[c],
                r.scores[rows],
                r.modes[rows],
                r.valid[rows],
                r.names,
                r.output_types,
                outcomes[c].mode,
                list(elements[c]),
                shown[c],
            )
        )
    return stats, U, r.modes.reshape(k, n), shown


def dither_stats(
    U: np.ndarray,
    scores: np.ndarray,
    modes: np.ndarray,
    valid: np.ndarray,
    names: list[str],
    types: Sequence[str],
    predicted_mode: int,
    elements: list[str],
    shown: np.ndarray | None = None,
) -> dict:
    """Reproducibility and neighbours of one dithered scenario (sections 4.4.5-4.4.7).

    How often the predicted mode shows, and (with ``shown``, a run's match of the whole
    predicted outcome) how often the pair's outcome does. Also how close the nearest run
    of another mode lies, and which sub-boundaries the neighbourhood holds that the pair
    does not test. An element that flips among runs of the predicted mode is *parallel*
    when it is of the same kind as the pair's elements (another no-go area), and
    *orthogonal* otherwise.
    """
    u = U[0]
    out: dict[str, Any] = {"runs": int(U.shape[0]), "valid": int(valid.sum())}
    if not valid.any():
        return out
    dist = np.linalg.norm(U[valid] - u, axis=1)
    if shown is not None:
        out["p_predicted"] = float(np.mean(shown[valid]))
    modes = modes[valid]
    out["p_predicted_mode"] = float(np.mean(modes == predicted_mode))
    out["modes"] = {MODE_NAMES[m]: int(c) for m, c in zip(*np.unique(modes, return_counts=True))}
    other = modes != predicted_mode
    out["nearest_other_mode"] = float(dist[other].min()) if other.any() else None
    same = scores[valid][~other]
    flips: list[dict[str, str | float]] = []
    if same.shape[0] > 1 and valid[0]:
        ref = scores[0]
        for c, (name, t) in enumerate(zip(names, types)):
            if t == "continuous" or "." not in name or name in elements:
                continue
            differ = same[:, c] != ref[c]
            if differ.any():
                kind = name.split(".")[0]
                relation = "parallel" if any(e.split(".")[0] == kind for e in elements) else "orthogonal"
                flips.append(
                    {
                        "element": name,
                        "relation": relation,
                        "share": float(differ.mean()),
                        "nearest": float(dist[~other][differ].min()),
                    }
                )
    out["sub_boundaries"] = sorted(flips, key=lambda f: f["nearest"])[:8]
    return out


# -- robust variants ---------------------------------------------------------------------------
#: Moves tried, in sigmas of the execution noise along the move, smallest first.
VARIANT_WAVES = ((1.0, 1.5, 2.0, 3.0), (4.0, 6.0, 8.0, 12.0, 16.0))
VARIANT_STEPS = tuple(step for wave in VARIANT_WAVES for step in wave)
VARIANT_COORDINATES = 2  # the most sensitive coordinates tried as directions
#: Variants confirmed with the full dithering per fragile scenario (screened best first).
VARIANT_CONFIRM = 2
#: Below the target, the best screened candidate is confirmed too when it screens at least this P.
CLOSEST_SCREENED = 0.7


def robust_variants(
    mission: Mission,
    fragile: np.ndarray,
    partners: np.ndarray,
    outcomes: Sequence[Outcome],
    dithers: Sequence[tuple[np.ndarray, np.ndarray]],
    sensitivity: np.ndarray,
    sigma: np.ndarray,
    n_screen: int,
    n_confirm: int,
    target: float,
    seed: int,
    surrogate=None,
) -> tuple[list[dict], int]:
    """For each fragile scenario, the smallest move away from its boundary that holds its outcome.

    ``dithers[s]`` holds the unit-cube rows of scenario ``s``'s dithers and whether each
    showed its outcome. Candidates step ``VARIANT_STEPS`` noise sigmas in each direction.
    A candidate must show the outcome in its deterministic run, and at least ``target``
    of ``n_screen`` dithers. The smallest such moves are then re-dithered with
    ``n_confirm`` runs, as the plan's own scenarios were, and the first to hold
    ``target`` wins (the smallest passing moves, and the best screened one, are confirmed).
    Returns an entry per scenario and the runs spent. Every entry has ``found``. A found
    variant has ``u``, ``p_predicted``, ``p_predicted_mode``, ``direction``, ``sigmas`` and
    ``moved``; otherwise ``reason`` says why not, ``best`` gives the best screened P, and
    ``closest`` (when any was confirmed) is the best confirmed variant under the target, in
    the found entries' form.
    """
    fragile = np.atleast_2d(np.asarray(fragile, dtype=float))
    sigma = np.asarray(sigma, dtype=float)
    out: list[dict] = [{"found": False, "reason": "", "best": None} for _ in range(len(fragile))]
    moves = [
        _moves(mission, u, partner, dithers[s], sensitivity, sigma)
        for s, (u, partner) in enumerate(zip(fragile, np.atleast_2d(partners)))
    ]
    runs = 0
    for wave in VARIANT_WAVES:  # small moves for every scenario first; larger ones only where they failed
        cands: list[np.ndarray] = []
        meta: list[tuple[int, str, float]] = []  # owner, direction, sigmas
        for s, m in enumerate(moves):
            if not out[s]["found"]:
                for name, step, w in m:
                    if step in wave:
                        cands.append(w)
                        meta.append((s, name, step))
        if not cands:
            continue
        runs += _try_variants(
            mission, fragile, outcomes, np.array(cands), meta, out, n_screen, n_confirm, sigma, target, seed, surrogate
        )
    for o, m in zip(out, moves):
        if not o["found"]:
            best = o.get("best")
            if not m:
                o["reason"] = "no parameter it can move carries execution noise"
                continue
            seen = "no candidate kept its outcome in its own run" if best is None else f"the best held {best:.0%}"
            o["reason"] = (
                f"no variant found: moves of up to {VARIANT_STEPS[-1]:g} noise sigmas away from the pair, "
                f"up the dithers' gradient or along the {VARIANT_COORDINATES} most sensitive parameters, "
                f"within the parameter ranges, held the outcome at P >= {target:g} ({seen})"
            )
    return out, runs


def _moves(mission, u, partner, dither, sensitivity, sigma) -> list[tuple[str, float, np.ndarray]]:
    """Candidate variants of ``u``: (direction, steps in noise sigmas, unit-cube row), per direction and step."""
    noisy = sigma > 0
    out = []
    for name, v in _directions(mission, u, partner, dither, sensitivity, sigma):
        z = np.where(noisy, v / np.where(noisy, sigma, 1.0), 0.0)  # the direction in noise sigmas
        if not np.any(z):
            continue
        unit_move = sigma * z / math.hypot(*z)  # one sigma of noise along v
        previous = u
        for step in VARIANT_STEPS:
            w = mission.space.snap(np.clip(u + step * unit_move, 0.0, 1.0)[None, :])[0]  # as the range sets it
            if np.allclose(w, previous):
                break  # pinned at the parameters' ranges
            out.append((name, step, w))
            previous = w
    return out


def _try_variants(mission, fragile, outcomes, V, meta, out, n_screen, n_confirm, sigma, target, seed, surrogate) -> int:
    """Screen and confirm one wave of candidates ``V`` (owners and moves in ``meta``); fill ``out``; runs spent."""
    owners = np.array([m[0] for m in meta])
    det = sim.uuv.simulate(mission, V, surrogate=surrogate)
    holds = np.zeros(len(V), dtype=bool)
    for s in np.unique(owners).tolist():
        rows = owners == s
        holds[rows] = outcomes[s].shown(det.scores[rows], det.valid[rows])
    p_screen = np.full(len(V), np.nan)
    keep = np.flatnonzero(holds)
    runs = len(V) + keep.size * n_screen
    if keep.size:
        p_screen[keep], _ = _p_shown(
            mission, V[keep], [outcomes[owners[i]] for i in keep], n_screen, sigma, seed, surrogate
        )
    confirm: list[int] = []
    for s in np.unique(owners).tolist():
        rows = np.flatnonzero((owners == s) & (p_screen >= target))
        rows = rows[np.argsort([meta[i][2] for i in rows], kind="stable")]  # smallest move first
        picked = rows[:VARIANT_CONFIRM].tolist()
        screened = np.flatnonzero((owners == s) & np.isfinite(p_screen))
        if len(screened) and not out[s].get("closest"):
            # and the best screened, even under the target: a small move that screens just above it may confirm
            # below it, and a side no move brings to the target still flies its most reliable variant
            best = int(screened[np.argmax(p_screen[screened])])
            picked += [best] if best not in picked and p_screen[best] >= CLOSEST_SCREENED else []
        confirm.extend(picked)
        seen = p_screen[owners == s]
        if not np.all(np.isnan(seen)):
            out[s]["best"] = max(float(np.nanmax(seen)), out[s]["best"] or 0.0)
    runs += len(confirm) * n_confirm
    if confirm:
        p_full, p_mode = _p_shown(
            mission, V[confirm], [outcomes[owners[i]] for i in confirm], n_confirm, sigma, seed + 1, surrogate
        )
        for i, p, pm in zip(confirm, p_full, p_mode):
            s, name, step = meta[i]
            if out[s]["found"]:
                continue
            entry = _variant_entry(mission, fragile[s], V[i], float(p), float(pm), name, step)
            if p >= target:
                out[s] = entry
            elif p > (out[s].get("closest") or {}).get("p_predicted", -1.0):
                out[s]["closest"] = entry  # the best confirmed under the target, for a caller that can use it
    return runs


def _variant_entry(mission: Mission, u: np.ndarray, w: np.ndarray, p: float, pm: float, name: str, step: float) -> dict:
    """A confirmed variant ``w`` of scenario ``u``: its row, confirmed P, and the move that made it."""
    c = int(np.argmax(np.abs(w - u)))
    return {
        "found": True,
        "u": [float(x) for x in w],
        "p_predicted": p,
        "p_predicted_mode": pm,
        "direction": name,
        "sigmas": step,
        "moved": {"parameter": mission.parameter_of(c), "unit_step": float(w[c] - u[c])},
        "unit_distance": math.dist(w, u),
    }


def _directions(mission, u, partner, dither, sensitivity, sigma) -> list[tuple[str, np.ndarray]]:
    """The directions a fragile scenario is moved in, named for the plan."""
    U, shown = dither
    out = [("away from the pair", u - partner)]
    if shown.any() and (~shown).any():
        out.append(("up the dithers' gradient", U[shown].mean(axis=0) - U[~shown].mean(axis=0)))
    order = [c for c in np.argsort(-sensitivity, kind="stable") if sigma[c] > 0][:VARIANT_COORDINATES]
    for c in order:
        v = np.zeros_like(u)
        v[c] = np.sign(u[c] - partner[c]) or 1.0
        out.append((f"along {mission.parameter_of(int(c))}", v))
    return out


def _p_shown(
    mission: Mission, V: np.ndarray, outcomes: Sequence[Outcome], n: int, sigma: np.ndarray, seed: int, surrogate
) -> tuple[np.ndarray, np.ndarray]:
    """Shares of ``n`` stochastic dithers of each row of ``V`` that show its outcome, and its mode."""
    k = V.shape[0]
    _, r = _dithered(mission, V, n, sigma, seed, surrogate)
    p, p_mode = np.zeros(k), np.zeros(k)
    for c in range(k):
        rows = slice(c * n, (c + 1) * n)
        valid = r.valid[rows]
        if valid.any():
            p[c] = float(outcomes[c].shown(r.scores[rows], valid)[valid].mean())
            p_mode[c] = float(np.mean(r.modes[rows][valid] == outcomes[c].mode))
    return p, p_mode


def _dithered(
    mission: Mission, centres: np.ndarray, n: int, sigma: np.ndarray, seed: int, surrogate
) -> tuple[np.ndarray, sim.uuv.Result]:
    """``n`` seeded Gaussian dithers of each centre, the first the centre itself, run stochastic in one batch
    (:func:`planner.common.execution_noise.dithered_runs`, shared with ``rapt-plan compare``'s forecast).

    Returns the dithers' unit-cube rows, (k, n, d), and their runs in that order (k * n rows).
    """
    return dithered_runs(mission, centres, n, sigma, seed, surrogate)
