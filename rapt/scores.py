"""Score kinds and their normalisation.

A simulation returns several scores at once: categorical labels (performance modes, or a
binary pass/fail, which is a two-class categorical) and continuous metrics (fuel left,
closest approach).  The information metrics need continuous scores on a common scale
(``Ȳ`` in ``[0, 1]``, section 3.3.1) and categorical scores as small integer codes.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["OUTPUT_TYPES", "check_output_types", "infer_output_types", "encode_labels", "normalize_continuous"]

OUTPUT_TYPES = ("categorical", "binary", "continuous")

#: A column with integral values and at most this many distinct values is inferred categorical.
MAX_INFERRED_CLASSES = 16


def check_output_types(output_types: Sequence[str], m: int) -> tuple[str, ...]:
    types = tuple(output_types)
    if len(types) != m:
        raise ValueError(f"output_types: got {len(types)} types for {m} score columns; give one per column")
    for t in types:
        if t not in OUTPUT_TYPES:
            raise ValueError(f"output_types: unknown type {t!r}; allowed: {', '.join(OUTPUT_TYPES)}")
    return types


def infer_output_types(Y: np.ndarray) -> tuple[str, ...]:
    """Guess each column's kind: integral with few values -> categorical (binary if two), else continuous."""
    Y = np.asarray(Y, dtype=float)
    types = []
    for col in Y.T:
        col = col[np.isfinite(col)]
        values = np.unique(col)
        if col.size and np.all(values == np.round(values)) and values.size <= MAX_INFERRED_CLASSES:
            types.append("binary" if values.size <= 2 and np.all(np.isin(values, (0.0, 1.0))) else "categorical")
        else:
            types.append("continuous")
    return tuple(types)


def encode_labels(column: np.ndarray) -> tuple[np.ndarray, int]:
    """Map arbitrary label values to codes ``0..C-1``; returns (codes, C)."""
    values, codes = np.unique(np.asarray(column), return_inverse=True)
    return codes.astype(np.int64), int(values.size)


def normalize_continuous(column: np.ndarray) -> np.ndarray:
    """Min-max scale to ``[0, 1]``; a constant column becomes all zeros."""
    col = np.asarray(column, dtype=float)
    lo, hi = float(col.min()), float(col.max())
    if hi <= lo:
        return np.zeros_like(col)
    return (col - lo) / (hi - lo)
