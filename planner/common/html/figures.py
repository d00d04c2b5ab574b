"""The reports' figures: matplotlib headless, figures saved and closed, mission areas drawn on a map.

Importing this module selects matplotlib's Agg backend: the reports write PNG files only,
on CI machines and range laptops without a display.  A map is drawn in local metres (east,
north); :func:`draw_area` fills one mission area (or outlines it), so the plan's maps (from
GeoJSON) and the comparison's (from the mission's rectangles) draw areas alike.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no display on CI machines or range laptops

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

__all__ = ["save_figure", "draw_area", "rectangle_corners", "label_map_axes"]


def save_figure(fig: Figure, path: Path, **savefig: Any) -> None:
    """Write ``fig`` to ``path`` (``savefig`` as matplotlib's) and close it, also when writing fails."""
    try:
        fig.savefig(path, **savefig)
    finally:
        plt.close(fig)


def draw_area(
    ax,
    corners: np.ndarray,
    *,
    face: str | None,
    edge: str,
    alpha: float | None = None,
    linewidth: float = 1.0,
    linestyle: str = "-",
    label: str | None = None,
) -> None:
    """A closed polygon of (east, north) ``corners``: filled with ``face``, or only outlined when it is None."""
    fill: dict[str, Any] = {"fill": False} if face is None else {"facecolor": face}
    ax.add_patch(
        Polygon(
            corners,
            closed=True,
            **fill,
            edgecolor=edge,
            alpha=alpha,
            linewidth=linewidth,
            linestyle=linestyle,
            label=label,
        )
    )


def rectangle_corners(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """The four corners of an axis-aligned rectangle, counter-clockwise from (x0, y0)."""
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def label_map_axes(ax) -> None:
    """A map's axes: metres east and north."""
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
