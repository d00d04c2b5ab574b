"""How often a policy under training ends a mission's scenarios in the expert's mode.

``rapt-plan surrogate --validate N`` reports after each imitation update the mode
accuracy of the policy so far.  The validation scenarios (the first N of a Sobol
sequence) and the expert's runs on them are drawn once, so every update is measured on
the same ground and the expert is not flown again.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from planner.surrogate import mode_agreement
from sim.uuv.mission import Mission

__all__ = ["ModeValidation"]


class ModeValidation:
    """``n`` Sobol scenarios of ``mission`` (seeded), flown once by the expert; call it with a policy."""

    def __init__(self, mission: Mission, n: int, seed: int = 0):
        import sim.uuv

        self.mission = mission
        self.X: np.ndarray = qmc.Sobol(mission.dim, seed=seed).random(n)
        self.expert = sim.uuv.simulate(mission, self.X)

    def __call__(self, policy) -> float:
        """Share of the valid validation scenarios where ``policy`` flies into the expert's mode."""
        from sim.uuv.imitation.surrogate import Surrogate

        return mode_agreement(self.mission, Surrogate.for_mission(self.mission, policy), self.X, self.expert)
