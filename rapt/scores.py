"""Score kinds and their normalisation.

A simulation returns several scores at once: categorical labels (performance modes, or a
binary pass/fail, which is a two-class categorical) and continuous metrics (fuel left,
closest approach).  The information metrics need continuous scores on a common scale
(``Ȳ`` in ``[0, 1]``, section 3.3.1) and categorical scores as small integer codes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rapt.errors import InputError

__all__ = [
    "OUTPUT_TYPES",
    "check_output_types",
    "infer_output_types",
    "encode_labels",
    "row_codes",
    "normalize_continuous",
]

OUTPUT_TYPES = ("categorical", "binary", "continuous")

#: A column with integral values and at most this many distinct values is inferred categorical.
MAX_INFERRED_CLASSES = 16


def check_output_types(output_types: Sequence[str], m: int) -> tuple[str, ...]:
    types = tuple(output_types)
    if len(types) != m:
        raise InputError(f"output_types: got {len(types)} types for {m} score columns; give one per column")
    for t in types:
        if t not in OUTPUT_TYPES:
            raise InputError(f"output_types: unknown type {t!r}; allowed: {', '.join(OUTPUT_TYPES)}")
    return types


def infer_output_types(Y: np.ndarray) -> tuple[str, ...]:
    """Guess each column's kind: integral with few values -> categorical (binary if two), else continuous.

    Vectorised over columns (no per-column sort), because a large study's score matrix
    has a million rows and dozens of columns.
    """
    Y = np.asarray(Y, dtype=float)
    columns = np.ascontiguousarray((Y[:, None] if Y.ndim == 1 else Y).T)
    types = []
    for col in columns:
        if not np.all(np.isfinite(col)):
            col = col[np.isfinite(col)]
        if col.size == 0 or col.max() - col.min() >= 2**20 or not np.all(col == np.rint(col)):
            types.append("continuous")
            continue
        lo, hi = col.min(), col.max()
        n_values = int(np.count_nonzero(np.bincount((col - lo).astype(np.int64))))
        if n_values > MAX_INFERRED_CLASSES:
            types.append("continuous")
        elif n_values <= 2 and lo >= 0 and hi <= 1:
            types.append("binary")
        else:
            types.append("categorical")
    return tuple(types)


def encode_labels(column: np.ndarray) -> tuple[np.ndarray, int]:
    """Map arbitrary label values to codes ``0..C-1``; returns (codes, C)."""
    values, codes = np.unique(np.asarray(column), return_inverse=True)
    return codes.astype(np.int64), int(values.size)


def row_codes(A) -> tuple[np.ndarray, int]:
    """Number the distinct rows of ``A``: (codes, count), codes in lexicographic row order.

    ``A`` is an (N, m) array or a sequence of m columns of length N.

    Same result as ``np.unique(A, axis=0, return_inverse=True)`` but built from per-column
    codes folded into one integer key (mixed radix, re-compressed before it can overflow),
    so it sorts integers instead of byte strings: the comparison that dominates on wide
    discrete score matrices, which is where a sub-boundary tree spends its splitting time.
    """
    if isinstance(A, np.ndarray):
        A = A[:, None] if A.ndim == 1 else A
        columns = list(np.ascontiguousarray(A.T))
    else:  # a sequence of 1-D columns, e.g. rows of an already transposed matrix
        columns = [np.asarray(c) for c in A]
    n = columns[0].shape[0]
    key = np.zeros(n, dtype=np.int64)
    span = 1
    for column in columns:
        codes, count = _column_codes(column)
        if span * count >= 2**62:  # compress before the key overflows
            _, key = np.unique(key, return_inverse=True)
            key = key.reshape(-1).astype(np.int64)
            span = int(key.max()) + 1 if n else 1
        key = key * count + codes
        span *= count
    values, inverse = np.unique(key, return_inverse=True)
    return inverse.reshape(-1).astype(np.int64), int(values.size)


def _column_codes(column: np.ndarray) -> tuple[np.ndarray, int]:
    """Rank codes of one column; small non-negative integers map to themselves (no sort)."""
    if column.size and np.issubdtype(column.dtype, np.number):
        lo, hi = column.min(), column.max()
        if lo >= 0 and hi < 4096 and np.all(column == np.floor(column)):
            return column.astype(np.int64), int(hi) + 1
    return encode_labels(column)


def normalize_continuous(column: np.ndarray) -> np.ndarray:
    """Min-max scale to ``[0, 1]``; a constant column becomes all zeros."""
    col = np.asarray(column, dtype=float)
    lo, hi = float(col.min()), float(col.max())
    if hi <= lo:
        return np.zeros_like(col)
    return (col - lo) / (hi - lo)
