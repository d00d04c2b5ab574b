"""Decoded scenario parameters as plain JSON values, for plans, comparisons and log metadata.

:meth:`rapt.space.StateSpace.decode` gives numpy scalars and tuples (a permutation);
``json.dumps`` takes neither, so every file the planner writes goes through these.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["json_value", "jsonable"]


def json_value(v: Any) -> Any:
    """A numpy scalar as its Python number, a tuple as a list; anything else unchanged."""
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, tuple):
        return list(v)
    return v


def jsonable(values: dict) -> dict:
    """``values`` with every value made a plain JSON value (:func:`json_value`)."""
    return {k: json_value(v) for k, v in values.items()}
