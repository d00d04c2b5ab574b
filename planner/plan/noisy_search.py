"""The search on a noisy system (section 4.2.3): stochastic runs, steered by continuous metrics as well as the modes.

With execution noise on, a binary score blurs into a fuzzy region where success and failure
mix, while a continuous metric (a closest approach, the energy left, the mission's time) is
its mean function plus Gaussian noise and jumps where the autonomy's decision changes
(Figure 4.10: the early return shows in the closest distance to the survey area, not in
mission success).  ``rapt-plan generate --noisy-search`` therefore runs the search on the
stochastic simulator (each run seeded from the study's seed and its scenario, so a study is
the same per seed and resumes) and steers S-NDV on the two root scores together with these
continuous metrics.  The pairs are still chosen from the study's modes and written, dithered
and judged as on the deterministic search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import sim.uuv
from sim.uuv.metrics import metric_names, metric_types
from sim.uuv.mission import Mission

__all__ = ["NoisyMissionScores", "NOISY_STORE", "noisy_columns", "search_record"]

#: The study store of a noisy search, beside (never replacing) a deterministic search's ``study.db``.
NOISY_STORE = "study-noisy.db"

#: Continuous leaves the noisy search steers on besides the root scores: every element's closest approach,
#: and the mission's time and energy left (section 4.3's "closest distance ... or fuel consumed").
NOISY_LEAVES = ("mission.time_s", "mission.battery_left")


def noisy_columns(mission: Mission) -> tuple[list[int], tuple[str, ...]]:
    """The score columns a noisy search steers on (root scores first) and their rapt output types."""
    names, types = metric_names(mission), metric_types(mission)
    cols = [0, 1] + [
        c
        for c, name in enumerate(names)
        if types[c] == "continuous" and (name.endswith(".closest_m") or name in NOISY_LEAVES)
    ]
    return cols, tuple(types[c] for c in cols)


@dataclass(frozen=True)
class NoisyMissionScores:
    """Every score of unit-cube scenarios run with the stochastic effects on (NaN rows for invalid ones).

    Each run's random stream comes from ``seed`` and the scenario's own values, so a row scores
    the same alone, in any batch and on any executor (picklable).
    """

    mission: Mission
    seed: int

    def __call__(self, U: np.ndarray) -> np.ndarray:
        return sim.uuv.simulate(self.mission, U, seed=self.seed, stochastic=True).scores


def search_record(mission: Mission, noisy: bool, surrogate: bool, root_columns: tuple[int, ...]) -> dict:
    """``study.search`` of ``plan.json``: the model the search ran on and the score columns that steered it."""
    names = metric_names(mission)
    cols = noisy_columns(mission)[0] if noisy else list(root_columns)
    model = "stochastic" if noisy else ("surrogate" if surrogate else "deterministic")
    return {"model": model, "steered_on": [names[c] for c in cols]}
