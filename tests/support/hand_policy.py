"""A hand-made linear back-seat policy for imitation7: a learner whose behaviour a test can predict."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import sim.uuv
from rapt.imitation.policies import MLPPolicy
from sim.uuv.imitation.features import FeatureSpec, feature_spec

IMITATION7 = sim.uuv.load_mission(Path(__file__).resolve().parents[2] / "examples" / "imitation7.toml")
SPEC = feature_spec(IMITATION7)


def steering_policy(home_below: float = 0.15, spec: FeatureSpec = SPEC) -> MLPPolicy:
    """A hand-made linear policy: ahead at 80% of max speed, turning away from sonar returns ahead,
    homing on the waypoint, and giving it up when the charge is below ``home_below``."""
    W = np.zeros((spec.size, 4), np.float32)
    sonar = np.arange(spec.size)[spec.sonar]
    if spec.observation == "scan":
        ahead_stbd, ahead_port = sonar[1:30], sonar[331:360]
        W[ahead_stbd, 1] = 0.05  # a return to starboard (feature < 1) lowers the starboard command: turn to port
        W[ahead_port, 1] = -0.05
    else:
        W[sonar[2::3], 1] = -1.5  # a remembered contact to starboard turns it to port, and the other way
    W[2, 1] = W[5, 1] = 0.5  # steer towards the waypoint (or, with none pending, the recovery point)
    W[0, 2] = -10.0  # the goal output is positive below the charge home_below (fuel feature 2 b - 1)
    b = np.array([0.8, -0.05 * 29 + 0.05 * 29, 10.0 * (2 * home_below - 1), 0.8], np.float32)
    return MLPPolicy([W], [b], "logistic")


class GreedyPolicy:
    """A learner that heads straight for its goal at cruise speed and gives the waypoint up below
    ``home_below`` charge: it collides with obstacles in its way, so its search shows several
    boundary types (fuel: SS/TS; collisions: TF or MS) at places a test can reason about."""

    def __init__(self, home_below: float = 0.15, spec: FeatureSpec = SPEC):
        self.home_below, self.spec = home_below, spec
        self.n_features, self.n_outputs = spec.size, spec.actions

    def __call__(self, F: np.ndarray, quiet=None) -> np.ndarray:
        F = np.asarray(F, dtype=float)
        pending = np.any(F[:, 1:4] != 0, axis=1)
        fwd = np.where(pending, F[:, 1], F[:, 4])
        stbd = np.where(pending, F[:, 2], F[:, 5])
        norm = np.maximum(np.hypot(fwd, stbd), 1e-9)
        goal = np.where((F[:, 0] + 1) / 2 < self.home_below, 1.0, -1.0)
        speed = np.full(F.shape[0], 2.0 / self.spec.max_speed)
        return np.column_stack([fwd / norm, stbd / norm, goal, speed]).astype(np.float32)
