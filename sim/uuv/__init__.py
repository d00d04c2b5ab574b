"""The UUV world: mission simulator, back-seat autonomy, scoring and a MAVLink front-seat.

Depends on :mod:`rapt` for shared types only; never imports :mod:`bridge`.
"""

from sim.uuv.bias import Bias, parse_bias
from sim.uuv.mission import Mission
from sim.uuv.missionfile import load_mission
from sim.uuv.simulate import Result, simulate

__all__ = ["Bias", "Mission", "Result", "simulate", "load_mission", "parse_bias"]
