"""Text and numbers on a report page: HTML-escaped, a missing value as a dash.

Both reports escape every text taken from a plan, a mission or a log.  They write a missing
number differently (the plan report an em dash, the comparison an en dash), so ``missing``
is each report's own.
"""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

__all__ = ["EM_DASH", "EN_DASH", "escape", "decimal", "significant", "percent"]

EM_DASH = "—"
EN_DASH = "–"


def escape(value: Any, none: str = "None") -> str:
    """``value`` as HTML text (quotes escaped too); ``None`` is written as ``none``."""
    return html.escape(none if value is None else str(value), quote=True)


def decimal(value: Any, digits: int = 3, *, missing: str) -> str:
    """A number with ``digits`` decimals (integers with thousands separators), very large or small ones in ``g``.

    ``missing`` stands for None, NaN and infinities; a value that is no number is escaped as text.
    """
    if value is None:
        return missing
    try:
        v = float(value)
    except (TypeError, ValueError):
        return escape(value)
    if not math.isfinite(v):
        return missing
    if v == int(v) and abs(v) < 1e12 and isinstance(value, (int, np.integer)):
        return f"{int(v):,}"
    return f"{v:.{digits}g}" if abs(v) >= 1e4 or (v != 0 and abs(v) < 1e-3) else f"{v:.{digits}f}"


def significant(value: Any, digits: int = 3, *, missing: str) -> str:
    """A float to ``digits`` significant digits; ``missing`` for None; anything else escaped as text."""
    if value is None:
        return missing
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return escape(value)


def percent(value: Any, *, missing: str) -> str:
    """A share in [0, 1] as a whole percentage (``0.25`` -> ``25%``); ``missing`` for None."""
    if value is None:
        return missing
    return f"{100.0 * float(value):.0f}%"
