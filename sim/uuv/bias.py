"""Execution bias: how a real vehicle on a real range departs from the simulator (section 4.5).

On the 2017 range day the vehicle ran faster than commanded and the tidal files were
wrong, so every run shifted the same way — an *execution bias*, unlike stochastic effects
a translation of all the performance boundaries.  A :class:`Bias` given to the world
(:class:`sim.uuv.world.World`, hence :func:`sim.uuv.simulate` and :class:`sim.uuv.ardusub.frontseat.FrontSeat`)
makes the vehicle behave like such a vehicle, while the back-seat autonomy still plans
with the unbiased model — the mission file's vehicle and tide table.  That is what makes
it a bias, and why ``rapt-plan compare`` can estimate it from logs.

==================  =======  ==========================================================
name                neutral  meaning
==================  =======  ==========================================================
``speed``           1.0      through-water speed achieved per unit commanded
                             (1.15: the vehicle runs 15 % faster than commanded)
``current_scale``   1.0      true tidal current / the tide table's
``current_offset``  0.0      m/s added to the tide along the mission's flood direction
                             (``[current] direction_deg``; negative: towards the ebb)
``current_cross``   0.0      m/s added across it, towards ``direction_deg + 90``: with
                             ``current_offset``, a steady current from any direction
``heading``         0.0      degrees the track through water runs clockwise of the bow
                             (fin trim, a misaligned compass or DVL): a crab the
                             autonomy does not know about
``battery``         1.0      energy the pack delivers per unit of charge the gauge shows
                             (1.1: the charge drains 10 % slower than the model, as if
                             the starting battery were higher)
``start_time``      0.0      seconds the true tide runs ahead of the tide table (a wrong
                             time zone or epoch in the tidal file)
==================  =======  ==========================================================

Written on the command line as ``speed=1.15,current_offset=0.3`` (:func:`parse_bias`);
omitted fields stay neutral.  The neutral bias changes nothing: the simulator's results
are bit-identical to a run without one.

**Composition.**  A mission file may carry the day's bias (``[execution_bias]``,
:mod:`sim.uuv.missionbias`): the water and vehicle the morning's logs showed.  A bias
given on top of it (``simulate(..., bias=)``, ``rapt-plan run --inject-bias``, a bias
fit in ``rapt-plan compare``) is *relative* to it, and the two compose field by field
(:func:`compose`): the scales multiply (``speed``, ``current_scale``, ``battery``), the
offsets add (``current_offset``, ``current_cross``, ``heading``, ``start_time``).  The world
then flies ``current = scale1*scale2 * tide(t + start1 + start2) + (offset1 + offset2)`` along
the flood direction and ``cross1 + cross2`` across it, a course ``heading1 + heading2`` clockwise of the bow, and so on: the
composition is exactly the bias a single argument would give, and composing with the
neutral bias returns the other bias's values unchanged (bit for bit).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from types import SimpleNamespace

import numpy as np

from rapt.errors import InputError

__all__ = [
    "Bias",
    "BiasArrays",
    "BIAS_NAMES",
    "BIAS_UNITS",
    "BIAS_LIMITS",
    "SCALE_FIELDS",
    "parse_bias",
    "bias_arrays",
    "compose",
    "compose_arrays",
]


@dataclass(frozen=True)
class Bias:
    """A vehicle's execution bias (see the module docstring for each field)."""

    speed: float = 1.0
    current_scale: float = 1.0
    current_offset: float = 0.0
    current_cross: float = 0.0
    heading: float = 0.0
    battery: float = 1.0
    start_time: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            check_value(f.name, getattr(self, f.name))

    @property
    def is_neutral(self) -> bool:
        return self == Bias()

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    def vector(self) -> np.ndarray:
        """The fields in :data:`BIAS_NAMES` order."""
        return np.array([getattr(self, n) for n in BIAS_NAMES], dtype=float)

    @classmethod
    def from_vector(cls, values: Sequence[float]) -> Bias:
        return cls(**{n: float(v) for n, v in zip(BIAS_NAMES, values)})

    def __str__(self) -> str:
        changed = [f"{n}={getattr(self, n):g}" for n in BIAS_NAMES if getattr(self, n) != NEUTRAL[n]]
        return ",".join(changed) or "none"


BIAS_NAMES: tuple[str, ...] = tuple(f.name for f in fields(Bias))
BIAS_UNITS: dict[str, str] = {
    "speed": "x",
    "current_scale": "x",
    "current_offset": "m/s",
    "current_cross": "m/s",
    "heading": "deg",
    "battery": "x",
    "start_time": "s",
}
#: Accepted range of each field (inclusive): wider than any plausible range day, narrow
#: enough to catch a value in the wrong unit (``heading=0.2`` rad is allowed, 90 is not).
BIAS_LIMITS: dict[str, tuple[float, float]] = {
    "speed": (0.5, 2.0),
    "current_scale": (0.0, 3.0),
    "current_offset": (-2.0, 2.0),
    "current_cross": (-2.0, 2.0),
    "heading": (-45.0, 45.0),
    "battery": (0.25, 4.0),
    "start_time": (-43200.0, 43200.0),
}
_EXAMPLE = "e.g. speed=1.15,current_offset=0.3"


def check_value(name: str, value) -> float:
    lo, hi = BIAS_LIMITS[name]
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: {value!r} is not a number; write {name}=<number>, {_EXAMPLE}") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise InputError(
            f"{name}: {value} is outside [{lo:g}, {hi:g}] {BIAS_UNITS[name]}; "
            f"give a value in that range (neutral: {NEUTRAL[name]:g})"
        )
    return v


#: The neutral bias's fields (the defaults: no change to the vehicle).
NEUTRAL: dict[str, float] = Bias().to_dict()


def parse_bias(text: str) -> Bias:
    """``"speed=1.15,current_offset=0.3"`` -> :class:`Bias`; InputError naming the bad field.

    An empty string or ``none`` is the neutral bias.
    """
    text = (text or "").strip()
    if text.lower() in ("", "none"):
        return Bias()
    values: dict[str, float] = {}
    for item in text.split(","):
        item = item.strip()
        if not item:
            raise InputError(f"empty item in {text!r}; separate name=value items by single commas, {_EXAMPLE}")
        name, eq, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if name not in BIAS_NAMES:
            raise InputError(f"{name}: unknown bias parameter; choose from {', '.join(BIAS_NAMES)} ({_EXAMPLE})")
        if not eq or not value:
            raise InputError(f"{name}: no value; write {name}=<number>, {_EXAMPLE}")
        if name in values:
            raise InputError(f"{name}: given twice; give each parameter once")
        values[name] = check_value(name, value)
    return Bias(**values)


@dataclass
class BiasArrays:
    """A bias per vehicle of a batch: each field an (N,) array; ``heading`` in radians."""

    speed: np.ndarray
    current_scale: np.ndarray
    current_offset: np.ndarray
    current_cross: np.ndarray
    heading_rad: np.ndarray
    battery: np.ndarray
    start_time: np.ndarray

    def select(self, rows: np.ndarray) -> BiasArrays:
        return BiasArrays(*(getattr(self, f.name)[rows] for f in fields(self)))


def bias_arrays(bias: Bias | BiasArrays | Sequence[Bias] | Mapping[str, np.ndarray] | None, n: int) -> BiasArrays:
    """Broadcast one bias, one per vehicle, or arrays by field name over ``n`` vehicles."""
    if bias is None:
        bias = Bias()
    if isinstance(bias, BiasArrays):
        if bias.speed.shape != (n,):
            raise InputError(f"bias: expected arrays for {n} vehicles, got {bias.speed.shape}")
        return bias
    if isinstance(bias, Bias):
        cols = {name: np.full(n, float(getattr(bias, name))) for name in BIAS_NAMES}
    elif isinstance(bias, Mapping):
        cols = {
            name: np.broadcast_to(np.asarray(bias.get(name, NEUTRAL[name]), dtype=float), (n,)).copy()
            for name in BIAS_NAMES
        }
    else:
        items = list(bias)
        if len(items) != n:
            raise InputError(f"bias: expected one Bias or {n} of them (one per scenario), got {len(items)}")
        cols = {name: np.array([float(getattr(b, name)) for b in items]) for name in BIAS_NAMES}
    return BiasArrays(
        cols["speed"],
        cols["current_scale"],
        cols["current_offset"],
        cols["current_cross"],
        np.deg2rad(cols["heading"]),
        cols["battery"],
        cols["start_time"],
    )


#: Fields that multiply when biases compose; the others (offsets) add (module docstring).
SCALE_FIELDS: tuple[str, ...] = ("speed", "current_scale", "battery")


def compose(base: Bias, relative):
    """The bias of ``relative`` applied on top of ``base``: scales multiply, offsets add.

    Not range-checked: a composed bias is what the world flies, not something a user
    typed, so it may leave :data:`BIAS_LIMITS` (two 1.5x speed biases make 2.25x).
    ``relative`` may also be any object with the fields as attributes (arrays of trial
    biases in a batched replay); the result is then a namespace of the same shape.
    """
    if base.is_neutral or (isinstance(relative, Bias) and relative.is_neutral):
        return relative if base.is_neutral else base
    values = {
        n: getattr(base, n) * getattr(relative, n) if n in SCALE_FIELDS else getattr(base, n) + getattr(relative, n)
        for n in BIAS_NAMES
    }
    if not isinstance(relative, Bias):
        return SimpleNamespace(**values)
    out = object.__new__(Bias)  # skip __post_init__'s limits (see above)
    for n, v in values.items():
        object.__setattr__(out, n, float(v))
    return out


def compose_arrays(relative: BiasArrays, base: Bias) -> BiasArrays:
    """Per-vehicle biases ``relative`` applied on top of one ``base`` bias (:func:`compose`).

    A neutral ``base`` returns ``relative`` itself, so a mission without a day's bias
    flies exactly as before.
    """
    if base.is_neutral:
        return relative
    return BiasArrays(
        relative.speed * base.speed,
        relative.current_scale * base.current_scale,
        relative.current_offset + base.current_offset,
        relative.current_cross + base.current_cross,
        relative.heading_rad + np.deg2rad(base.heading),
        relative.battery * base.battery,
        relative.start_time + base.start_time,
    )
