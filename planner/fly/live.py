"""A run's Foxglove live view, in a process of its own (:class:`bridge.live_process.LiveViewProcess`) joined to
the run's bus and handed the scenario's map: the run's own process commands the vehicle, and shares its
interpreter with nothing the view does."""

from __future__ import annotations

from bridge.live_process import LiveViewProcess
from planner.fly.run_bus import RunBus
from planner.fly.scenario_map import SCENARIO_MAP, scenario_map
from sim.uuv.mission import Mission

__all__ = ["start_live_view"]


def start_live_view(
    bus: RunBus, vehicle: str, mission: Mission, u, live: tuple[str, int] | None
) -> LiveViewProcess | None:
    """The live view on ``live`` = ``(host, port)`` (None: no view), on the bus as a reader (the logger's role),
    showing scenario ``u``'s map from the start (the bus carries it only once a logger appears)."""
    if live is None:
        return None
    host, port = live
    document = scenario_map(mission, u)
    maps = {SCENARIO_MAP: document} if document is not None else {}
    access = bus.view_joined()
    return LiveViewProcess(vehicle=vehicle, host=host, port=port, maps=maps, **access).start()
