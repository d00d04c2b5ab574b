"""Small hand-built missions for the simulator tests: one behaviour each, no file parsing."""

from __future__ import annotations

import dataclasses

import numpy as np

from rapt.space import Continuous, StateSpace
from sim.uuv.mission import Binding, Current, Mission, MissionArea, Rect, Transmission, Triangle, Vehicle


def mission(**overrides) -> Mission:
    """A 2x2 km box, launch and recovery in the south, one waypoint north; no current.

    One parameter (start time) so the unit cube is 1-D unless ``space``/``bindings`` are given.
    """
    base = dict(
        name="test",
        origin_lat=47.7,
        origin_lon=-122.6,
        operational_area=Rect("op", 0.0, 0.0, 2000.0, 2000.0),
        launch=(0.0, -800.0),
        recovery=(0.0, -820.0),
        recovery_radius=15.0,
        waypoints=((0.0, 0.0),),
        mission_areas=(),
        priority=(),
        transmission=None,
        nogo=(),
        barriers=(),
        obstacles=(),
        vehicle=Vehicle(battery_wh=2000.0),
        current=Current(speed=0.0, perturbation=0.0),
        start_time_s=0.0,
        time_limit_s=3600.0,
        waypoint_radius=25.0,
        space=StateSpace([Continuous("start_time", 0.0, 43200.0)]),
        bindings=(Binding("start_time", "mission", None, "start_time_s"),),
        score_tree={},
        mission_requires=("waypoints",),
        dt=2.0,
    )
    base.update(overrides)
    return Mission(**base)


def vehicle(**kw) -> Vehicle:
    return dataclasses.replace(Vehicle(battery_wh=2000.0), **kw)


def area(name, x, y, dwell=60.0, size=200.0) -> MissionArea:
    return MissionArea(name, x, y, size, size, dwell)


__all__ = ["mission", "vehicle", "area", "Rect", "Triangle", "Transmission", "Current", "np"]
