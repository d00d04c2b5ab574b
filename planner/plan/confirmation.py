"""The expert's confirmation of the surrogate's boundary pairs (section 6.2.3, step 3).

A pair found on a surrogate is worth planning only where the real autonomy (the expert)
changes its outcome too.  Even a good surrogate places its boundaries a little off the
expert's (a battery boundary shifted by ~0.02 of the unit cube), while an adaptive search
makes its pairs short, so running the expert at the pair's two ends alone rejects real
boundaries.  :func:`confirm_pairs` therefore looks for the expert's boundary *near* the
surrogate's: along the line through the pair, within ``radius`` of its ends, stepping
outward with doubling steps on the side where the expert's outcomes say the boundary
must lie, then bisecting the bracket it finds.  The planned pair is the expert's own
bracket.  The expert runs in batches over all candidates under way (the simulator is much
cheaper per run in a batch) and never beyond the ``budget`` of expert runs.

An *outcome* is the tuple of a run's discrete scores at the candidate's score-tree level;
at the root level that is the mode (mission and safety success).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import rapt
import sim.uuv
from rapt.errors import InputError
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES, modes_from_scores

__all__ = ["DEFAULT_RADIUS", "DEFAULT_MIN_LENGTH", "Confirmation", "confirm_pairs"]

DEFAULT_RADIUS = 0.05  # how far past the pair's ends the expert's boundary is looked for (unit cube)
DEFAULT_MIN_LENGTH = 0.005  # a bracket is not bisected below this length (unit cube)
INVALID = None  # the outcome of a scenario the simulator refuses


@dataclass
class Confirmation:
    """What the expert's check gave: the confirmed pairs and its accounting."""

    pairs: list[dict]
    candidates: int  # candidate pairs offered
    examined: int  # candidates the expert ran at all
    runs: int  # expert runs spent

    @property
    def share_confirmed(self) -> float:
        return len(self.pairs) / self.examined if self.examined else 0.0


@dataclass
class _Bracketing:
    """One candidate under way: the expert's outcomes at positions ``t`` along its line."""

    index: int
    pair: dict
    a: np.ndarray
    direction: np.ndarray
    length: float
    claimed: tuple  # the surrogate's outcomes at a and b
    t_min: float  # how far the line may go before a (negative) and past b
    t_max: float
    step: float
    target: float
    seen: dict[float, tuple | None] = field(default_factory=dict)
    scores: dict[float, np.ndarray] = field(default_factory=dict)  # the expert's score rows at ``t``
    sides: list[int] = field(default_factory=list)  # -1: before a, +1: past b
    last: dict[int, float] = field(default_factory=dict)  # the outermost position run on each side
    bracket: tuple[float, float] | None = None
    done: bool = False
    confirmed: bool = False

    def point(self, t: float) -> np.ndarray:
        return np.clip(self.a + t * self.direction, 0.0, 1.0)

    def requests(self) -> list[float]:
        """Positions the expert must run next (none once done)."""
        if self.done:
            return []
        if not self.seen:
            return [0.0, self.length]
        if self.bracket is not None:
            return [0.5 * (self.bracket[0] + self.bracket[1])]
        out = []
        for s in self.sides:
            reach = self.last[s] - self.length if s > 0 else -self.last[s]  # how far past its end so far
            d = min(2 * reach if reach else self.step, self._limit(s))
            out.append(self.length + d if s > 0 else -d)
        return out

    def _limit(self, s: int) -> float:
        """How far past its end side ``s`` may go (radius and unit cube)."""
        return self.t_max - self.length if s > 0 else -self.t_min

    def record(self, results: dict[float, tuple | None]) -> None:
        """Take the expert's outcomes at the requested positions and decide the next move."""
        first = not self.seen
        self.seen.update(results)
        if first:
            self._after_ends()
        elif self.bracket is not None:
            self._bisect(next(iter(results.values())))
        else:
            self._after_steps(results)
        if self.bracket is not None and not self.done and self.bracket[1] - self.bracket[0] <= self.target * (1 + 1e-9):
            self.done = self.confirmed = True

    def _after_ends(self) -> None:
        ka, kb = self.seen[0.0], self.seen[self.length]
        if ka is INVALID or kb is INVALID:
            self.done = True
        elif ka != kb:
            self.bracket = (0.0, self.length)
            self.done = self.confirmed = True  # confirmed as is
        else:  # the expert shows one outcome at both ends: its boundary lies past the end it agrees with
            self.sides = [+1] if ka == self.claimed[0] else [-1] if ka == self.claimed[1] else [-1, +1]
            self.sides = [s for s in self.sides if self._limit(s) > 1e-12]
            self.last = {+1: self.length, -1: 0.0}
            self.done = not self.sides

    def _after_steps(self, results: dict[float, tuple | None]) -> None:
        for t, k in results.items():
            s = 1 if t > self.length else -1
            near, self.last[s] = self.last[s], t  # the previous point on this side, and the new outermost
            if k is INVALID:
                self.sides.remove(s)
            elif k != self.seen[near]:
                self.bracket = (min(near, t), max(near, t))
                self.sides = []
                return
            elif abs(t - (self.length if s > 0 else 0.0)) >= self._limit(s) - 1e-12:
                self.sides.remove(s)
        self.done = not self.sides

    def _bisect(self, k: tuple | None) -> None:
        lo, hi = self.bracket  # type: ignore[misc]
        mid = 0.5 * (lo + hi)
        if k is INVALID:  # keep the expert's bracket as it stands
            self.done = self.confirmed = True
        elif k != self.seen[lo]:
            self.bracket = (lo, mid)
        else:
            self.bracket = (mid, hi)


def confirm_pairs(
    mission: Mission,
    candidates: list[dict],
    k: int,
    budget: int,
    radius: float = DEFAULT_RADIUS,
    min_length: float = DEFAULT_MIN_LENGTH,
) -> Confirmation:
    """The expert's own boundary pairs near the surrogate's candidates; up to ``k``, within ``budget`` runs.

    Each candidate holds ``u`` (its two unit-cube scenarios a and b), ``scores`` (the
    surrogate's score rows at them), ``level`` and ``modes``.  The expert runs a and b: if
    its outcomes differ there, the pair is confirmed as is.  Otherwise it steps past b (the
    expert shows the surrogate's outcome at a on both ends), before a (the outcome at b), or
    both ways (neither), with steps doubling from the pair's own length up to ``radius``
    and never out of the unit cube; an invalid scenario ends a side.  A bracket where the
    expert's outcomes differ is bisected to the pair's own length (at least
    ``min_length``).  Candidates are taken in order, no more under way at once than pairs
    still wanted, until ``k`` are confirmed, the candidates run out or the next run would
    exceed ``budget``.  Deterministic: no randomness.

    A confirmed pair carries the expert's bracket (``u_override``, ``distance``), its
    ``modes``, ``level`` and ``elements`` (the shallowest score-tree level where its
    discrete scores differ: the boundary type the expert shows, which may differ from the
    surrogate's ``surrogate_modes`` and ``surrogate_elements``), ``moved_by`` (unit-cube
    distance from the candidate's midpoint to the bracket's) and its ``expert_runs``.
    """
    if radius <= 0 or min_length <= 0:
        raise InputError(f"confirm_pairs: radius and min_length must be positive, got {radius} and {min_length}")
    levels = [list(cols) for cols in rapt.ScoreTree.from_mapping(mission.score_tree).levels()]
    names, types = metric_names(mission), metric_types(mission)
    discrete = [[c for c in cols if types[c] != "continuous"] for cols in levels]
    queue = [_start(i, p, discrete[p["level"]], radius, min_length) for i, p in enumerate(candidates)]
    active: list[_Bracketing] = []
    finished: list[_Bracketing] = []
    spent = 0
    while True:
        wanted = k - sum(b.confirmed for b in finished)
        while queue and len(active) < wanted:
            active.append(queue.pop(0))
        batch: list[tuple[_Bracketing, list[float]]] = []
        rows = 0
        for b in active:
            ts = b.requests()
            if spent + rows + len(ts) > budget:
                b.done = True  # the budget ends it
                continue
            batch.append((b, ts))
            rows += len(ts)
        if not batch:
            finished.extend(active)
            break
        U = np.array([b.point(t) for b, ts in batch for t in ts])
        r = sim.uuv.simulate(mission, U)
        spent += len(U)
        row = 0
        for b, ts in batch:
            cols = discrete[b.pair["level"]]
            got = {}
            for t in ts:
                got[t] = _outcome(r.scores[row], cols) if r.valid[row] else INVALID
                b.scores[t] = r.scores[row]
                row += 1
            b.record(got)
        finished.extend(b for b in active if b.done)
        active = [b for b in active if not b.done]
    confirmed = sorted((b for b in finished if b.confirmed), key=lambda b: b.index)[:k]
    return Confirmation(
        [_confirmed_pair(b, discrete, names) for b in confirmed],
        len(candidates),
        len([b for b in finished if b.seen]),
        spent,
    )


def _start(index: int, pair: dict, cols: list[int], radius: float, min_length: float) -> _Bracketing:
    a, b = (np.asarray(u, dtype=float) for u in pair["u"])
    length = math.dist(b, a)
    if length <= 0:
        raise InputError(f"confirm_pairs: candidate {index + 1} has two equal scenarios")
    direction = (b - a) / length
    scores = np.asarray(pair["scores"], dtype=float)
    # how far the line stays in the unit cube before a and past b
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(direction > 0, (1 - a) / direction, np.where(direction < 0, -a / direction, np.inf))
        down = np.where(direction > 0, -a / direction, np.where(direction < 0, (1 - a) / direction, -np.inf))
    return _Bracketing(
        index=index,
        pair=dict(pair),
        a=a,
        direction=direction,
        length=length,
        claimed=(_outcome(scores[0], cols), _outcome(scores[1], cols)),
        t_min=max(float(down.max()), -radius),
        t_max=min(float(up.min()), length + radius),
        step=float(np.clip(length, min_length, radius)),
        target=max(length, min_length),
    )


def _outcome(scores: np.ndarray, cols: list[int]) -> tuple:
    return tuple(float(v) for v in np.nan_to_num(scores[cols], nan=-1.0))


def _confirmed_pair(b: _Bracketing, discrete: list[list[int]], names: list[str]) -> dict:
    lo, hi = b.bracket  # type: ignore[misc]
    ends = np.vstack([b.scores[lo], b.scores[hi]])
    modes = modes_from_scores(ends)
    level = next(lv for lv, cols in enumerate(discrete) if _outcome(ends[0], cols) != _outcome(ends[1], cols))
    elements = [names[c] for c in discrete[level] if _outcome(ends[0], [c]) != _outcome(ends[1], [c])]
    pair = {key: v for key, v in b.pair.items() if key not in ("u", "scores", "rows")}
    return {
        **pair,
        "level": level,
        "elements": elements,
        "distance": float(hi - lo),
        "u_override": [b.point(lo).tolist(), b.point(hi).tolist()],
        "modes": [MODE_NAMES[m] for m in modes],
        "confirmed_by_expert": True,
        "surrogate_modes": list(b.pair["modes"]),
        "surrogate_elements": list(b.pair.get("elements", [])),
        "moved_by": float(abs(0.5 * (lo + hi) - 0.5 * b.length)),
        "expert_runs": len(b.seen),
    }
