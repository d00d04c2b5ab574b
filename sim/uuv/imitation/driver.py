"""A learned policy in the back seat: the expert's interface, the surrogate's decisions.

:class:`PolicyAutonomy` has the :class:`sim.uuv.autonomy.Autonomy` interface (``step(obs, dt,
active)`` returns a :class:`~sim.uuv.autonomy.Command`), so the batch simulator, the software-
in-the-loop back-seat and the scorer drive it exactly as they drive the expert.  Its
decisions are the policy's velocity vector (section 6.5.3); it surfaces on arrival at the
recovery point once it has been away from it (reaching the recovery point is what the
dissertation's surrogate is scored on).  Its memory is the expert's: the sonar contacts
seen in the last 30 s (:mod:`sim.uuv.contact_memory`, under the ``contacts`` observation
model), the next waypoint (advanced on arrival) and whether its own goal output has
turned it home, which it latches as the expert latches its return.  It does not know why it turned home, so the
"return reason" score leaf reads "none".
"""

from __future__ import annotations

import numpy as np

from sim.uuv.autonomy import GOAL_RETURN, GOAL_WAYPOINT, Command, Observation
from sim.uuv.contact_memory import ContactMemory
from sim.uuv.imitation.features import (
    GOAL,
    FeatureSpec,
    action_command,
    advance_waypoints,
    features,
    obstacle_view,
    predicted_current,
    waypoint_target,
)
from sim.uuv.scenario import Scenarios

__all__ = ["PolicyAutonomy", "AWAY_RADII"]

#: The vehicle has "been away" from the recovery point beyond this many recovery radii.
AWAY_RADII = 3.0


class PolicyAutonomy:
    """N vehicles of ``scen`` flown by ``policy`` (features -> actions) under ``spec``."""

    def __init__(self, scen: Scenarios, policy, spec: FeatureSpec, goal_threshold: float = 0.0):
        m = scen.mission
        self.scen, self.mission, self.policy, self.spec = scen, m, policy, spec
        n = scen.n
        self.goal_threshold = float(goal_threshold)  # the goal output above which the waypoint is given up
        self.wp_next = np.zeros(n, dtype=np.int64)
        self.away = np.zeros(n, dtype=bool)
        self.wp_aborted = np.zeros((n, len(m.waypoints)), dtype=bool)
        self.return_reason = np.zeros(n, dtype=np.int64)
        self.goal_kind = np.full(n, GOAL_WAYPOINT, dtype=np.int64)
        self.home = np.zeros(n, dtype=bool)  # the policy has given the waypoints up (latched)
        self.was_home = self.home.copy()  # ... before the last step
        self.last_target: tuple[np.ndarray, np.ndarray, np.ndarray] | None = (
            None  # (x, y, pending) of the next waypoint
        )
        self.last_features: np.ndarray | None = None
        self.memory = ContactMemory(spec.memory_s)
        self.last_view: np.ndarray | None = None  # the obstacle view the last decision saw
        self.last_tide: tuple[np.ndarray, np.ndarray] | None = None  # and the tide it predicted

    def step(self, obs: Observation, dt: float, active: np.ndarray | None = None) -> Command:
        m = self.mission
        view = self.last_view = obstacle_view(self.spec, self.memory, obs)
        self.wp_next = advance_waypoints(m, self.wp_next, obs.x, obs.y)
        wx, wy, pending = self.last_target = waypoint_target(m, self.wp_next)
        self.was_home = self.home.copy()
        pending = pending & ~self.home
        tide = self.last_tide = predicted_current(m, self.scen, obs)
        F = features(self.spec, m, obs.t, obs.x, obs.y, obs.heading, obs.battery, view, (wx, wy, pending), tide)
        self.last_features = F  # what the goal decision was taken on
        action = self.policy(F, quiet=self.spec.quiet)
        turn = pending & (action[:, GOAL] > self.goal_threshold)
        if np.any(turn):  # the decision takes effect at once: steer again with no waypoint pending
            rows = np.flatnonzero(turn)
            G = features(
                self.spec,
                m,
                obs.t,
                obs.x[rows],
                obs.y[rows],
                obs.heading[rows],
                obs.battery[rows],
                view[rows],
                (wx[rows], wy[rows], np.zeros(rows.size, dtype=bool)),
                (tide[0][rows], tide[1][rows]),
            )
            action[rows] = self.policy(G, quiet=self.spec.quiet)
        self.home |= turn if active is None else turn & active
        heading, speed = action_command(self.spec, obs.heading, action)
        rx, ry = m.recovery
        home = np.hypot(obs.x - rx, obs.y - ry)
        self.away |= home > AWAY_RADII * m.recovery_radius
        surface = self.away & (home <= m.recovery_radius)
        self.goal_kind = np.where(pending & ~turn, GOAL_WAYPOINT, GOAL_RETURN)
        return Command(heading, speed, surface)
