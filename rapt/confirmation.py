"""Confirming boundaries with a fixed budget of runs: when a side has shown, and which run to fly next.

A boundary pair is confirmed on the water when each of its two sides shows its predicted
outcome.  One run of a side is one Bernoulli draw: near a boundary the same scenario can
come out either way, with an unknown per-run probability ``q``.

**The rule** (:func:`evidence`, :func:`side_status`).  A side has *shown* when the runs
flown of it say, with odds of at least 3 to 1, that it shows its outcome more often than
not: ``P(q > 1/2 | its runs) >= CONFIDENCE`` under a uniform prior on ``q``.  It is a
Bayesian sequential test: the posterior is valid however many runs are flown and whenever
the flying stops (the likelihood principle), so a side may be flown again after a miss
without the error bookkeeping a Wald test would need.  The uniform prior keeps the
verdict the water's alone: the model's forecast does not count as evidence.  One run that
shows is enough (``P = 0.75``), as a range flying each side once expects; after a miss, the
side needs a clear majority (3 of 4).  ``P(q > 1/2) <= 1 - CONFIDENCE`` is the mirror
verdict, *against*: the side does not show its outcome here.

**The value of a run** (:func:`p_shown_within`, :func:`pair_curve`, :func:`allocate`,
:func:`next_run`).  For planning, the model's forecast ``p`` is a prior worth :data:`PRIOR_RUNS`
runs, updated by the runs flown (a Beta posterior), and gives the chance each next run
shows.  A side's curve is the chance it has shown within ``r`` more runs, flown until it
shows; a pair's, the best split of ``r`` between its sides (their product); the day's value,
the best split of the runs left between the pairs (an exact knapsack).  :func:`next_run`
looks one run ahead: it flies the run whose outcome, either way, leaves the largest expected
number of pairs confirmed by the end of the day, and stops when no run raises it.

Sides are taken as independent given their forecasts (a day's shared bias moves them
together; the forecasts carry it, the planning does not).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.stats import beta

__all__ = [
    "CONFIDENCE",
    "PRIOR_RUNS",
    "STOP_GAIN",
    "Option",
    "Side",
    "Pair",
    "Choice",
    "evidence",
    "side_status",
    "p_shown_within",
    "pair_curve",
    "allocate",
    "next_run",
]

#: A side has shown when P(it shows its outcome more often than not | its runs) reaches this (3:1 odds).
CONFIDENCE = 0.75
#: How many runs' worth of evidence the model's forecast counts for, when planning (never when confirming).
PRIOR_RUNS = 4.0
#: A run is worth flying when it raises the expected pairs confirmed by the end of the day by at least this.
STOP_GAIN = 1e-3
#: A pair whose chance of confirmation, with every run left spent on it, is below this is lost.
LOST_BELOW = 0.05


def evidence(shown: int, missed: int) -> float:
    """P(q > 1/2) after ``shown`` runs that showed the outcome and ``missed`` that did not (uniform prior)."""
    return float(beta.sf(0.5, 1 + shown, 1 + missed))


def side_status(shown: int, missed: int) -> str:
    """``shown``, ``against`` or ``open`` by the rule (module docstring)."""
    e = evidence(shown, missed)
    if e >= CONFIDENCE - 1e-12:
        return "shown"
    if e <= 1.0 - CONFIDENCE + 1e-12:
        return "against"
    return "open"


@dataclass(frozen=True)
class Option:
    """A scenario that can be flown for a pair side: its forecast P(shows) per run and its record so far."""

    p: float
    shown: int = 0
    missed: int = 0

    @property
    def status(self) -> str:
        return side_status(self.shown, self.missed)

    @property
    def p_next(self) -> float:
        """The chance the next run shows: the forecast as a prior of :data:`PRIOR_RUNS` runs, updated by the record."""
        p = min(max(self.p, 1e-6), 1 - 1e-6)
        return (PRIOR_RUNS * p + self.shown) / (PRIOR_RUNS + self.shown + self.missed)

    def after(self, showed: bool) -> Option:
        return replace(self, shown=self.shown + showed, missed=self.missed + (not showed))


@dataclass(frozen=True)
class Side:
    """A pair side: the scenarios that can be flown for it (the one flown so far first, then moves)."""

    options: tuple[Option, ...]

    @property
    def shown(self) -> bool:
        return any(o.status == "shown" for o in self.options)


@dataclass(frozen=True)
class Pair:
    """A boundary's pair: two sides, and any replacement pairs across the same boundary (one confirmed is enough)."""

    sides: tuple[Side, Side]
    replacements: tuple[Pair, ...] = ()

    @property
    def own_confirmed(self) -> bool:
        return self.sides[0].shown and self.sides[1].shown

    @property
    def confirmed(self) -> bool:
        return self.own_confirmed or any(r.confirmed for r in self.replacements)

    @property
    def alternatives(self) -> tuple[Pair, ...]:
        """The pair itself, then its replacements (the ``alternative`` index of a :class:`Choice`)."""
        return (self, *self.replacements)


@lru_cache(maxsize=65536)
def _curve(p: float, shown: int, missed: int, runs: int) -> tuple[float, ...]:
    """P(the option has shown within r more runs), r = 0..runs, flying it until it shows."""
    start = Option(p, shown, missed)
    if start.status == "shown":
        return (1.0,) * (runs + 1)
    out = [0.0]
    states = {(shown, missed): 1.0}  # not yet shown, by record
    done = 0.0
    for _ in range(runs):
        nxt: dict[tuple[int, int], float] = {}
        for (k, f), w in states.items():
            q = Option(p, k, f).p_next
            for (k2, f2), pw in (((k + 1, f), q), ((k, f + 1), 1.0 - q)):
                if side_status(k2, f2) == "shown":
                    done += w * pw
                else:
                    nxt[(k2, f2)] = nxt.get((k2, f2), 0.0) + w * pw
        states = nxt
        out.append(done)
    return tuple(out)


def p_shown_within(option: Option, runs: int) -> np.ndarray:
    """The option's curve: P(shown within r more runs) for r = 0..``runs``."""
    return np.array(_curve(round(float(option.p), 6), option.shown, option.missed, runs))


def _side_curve(side: Side, runs: int) -> np.ndarray:
    if side.shown:
        return np.ones(runs + 1)
    return np.max([p_shown_within(o, runs) for o in side.options], axis=0)


def pair_curve(pair: Pair, runs: int) -> np.ndarray:
    """P(the pair is confirmed within r more runs), r = 0..``runs``: the best split between its sides, or the best
    of its replacements' (the runs go to one of them)."""
    a, b = (_side_curve(s, runs) for s in pair.sides)
    own = np.array([max(a[i] * b[r - i] for i in range(r + 1)) for r in range(runs + 1)])
    return np.max([own, *(pair_curve(r, runs) for r in pair.replacements)], axis=0)


def allocate(curves: Sequence[np.ndarray], runs: int) -> tuple[float, list[int]]:
    """The split of ``runs`` between pairs that maximises the expected pairs confirmed (exact, by dynamic programming)."""
    best = np.zeros(runs + 1)  # value of the pairs so far with r runs
    choice: list[np.ndarray] = []
    for c in curves:
        value = np.full(runs + 1, -1.0)
        arg = np.zeros(runs + 1, dtype=int)
        for r in range(runs + 1):
            for i in range(r + 1):
                v = best[r - i] + c[i]
                if v > value[r] + 1e-12:
                    value[r], arg[r] = v, i
        best = value
        choice.append(arg)
    split, r = [], runs
    for arg in reversed(choice):
        split.append(int(arg[r]))
        r -= int(arg[r])
    return float(best[runs]), split[::-1]


def _value(pairs: Sequence[Pair], runs: int) -> float:
    return allocate([pair_curve(p, runs) for p in pairs], runs)[0]


@dataclass(frozen=True)
class Choice:
    """The run :func:`next_run` chose (None: stop), the expected pairs confirmed with it and without more runs."""

    pair: int | None
    side: int | None
    option: int | None
    expected: float  # expected pairs confirmed by the end of the day, flying this run first
    now: float  # pairs confirmed now
    p_confirm: list[float]  # per pair: its chance of confirmation under the day's best split of the runs left
    lost: list[bool]
    alternative: int = 0  # which of the pair's :attr:`Pair.alternatives` the run is of (0: the pair itself)


def _with(pairs: Sequence[Pair], i: int, a: int, j: int, k: int, showed: bool) -> list[Pair]:
    alts = list(pairs[i].alternatives)
    side = alts[a].sides[j]
    opts = list(side.options)
    opts[k] = opts[k].after(showed)
    sides = list(alts[a].sides)
    sides[j] = Side(tuple(opts))
    alts[a] = replace(alts[a], sides=(sides[0], sides[1]))
    out = list(pairs)
    out[i] = replace(alts[0], replacements=tuple(alts[1:]))
    return out


def next_run(pairs: Sequence[Pair], runs_left: int) -> Choice:
    """The run (pair, side, option) that most raises the expected pairs confirmed by the day's end, or stop."""
    now = float(sum(p.confirmed for p in pairs))
    curves = [pair_curve(p, max(runs_left, 0)) for p in pairs]
    _, split = allocate(curves, max(runs_left, 0))
    p_confirm = [float(c[r]) for c, r in zip(curves, split)]
    lost = [not p.confirmed and float(c[-1]) < LOST_BELOW for p, c in zip(pairs, curves)]
    best: tuple[float, float, int, int, int, int] | None = None
    for i, a, j, k, opt in _runs(pairs) if runs_left > 0 else ():
        q = opt.p_next
        v = q * _value(_with(pairs, i, a, j, k, True), runs_left - 1)
        v += (1 - q) * _value(_with(pairs, i, a, j, k, False), runs_left - 1)
        # equal values: the run most likely to settle its side at once (fewer runs spent)
        settles = q if opt.after(True).status == "shown" else 0.0
        if best is None or v > best[0] + 1e-9 or (v > best[0] - 1e-9 and settles > best[1] + 1e-9):
            best = (v, settles, i, a, j, k)
    if best is None or best[0] < now + STOP_GAIN:
        return Choice(None, None, None, now, now, p_confirm, lost)
    v, _, i, a, j, k = best
    return Choice(i, j, k, v, now, p_confirm, lost, a)


def _runs(pairs: Sequence[Pair]):
    """Every run that could be flown: (pair, alternative, side, option, the option) of each unconfirmed pair."""
    for i, pair in enumerate(pairs):
        if pair.confirmed:
            continue
        for a, alt in enumerate(pair.alternatives):
            for j, side in enumerate(alt.sides):
                if not side.shown:
                    for k, opt in enumerate(side.options):
                        yield i, a, j, k, opt
