"""How well a surrogate reproduces a system's performance modes and boundaries (section 6.3.4).

Both systems are run on the same validation scenarios (a Sobol design in the paper); the
figures compare their labels there:

* **mode accuracy** — share of scenarios where the surrogate shows the system's mode, and
  the confusion matrix (rows: the system's mode, columns: the surrogate's; Figure 6.7);
* **path error** — mean distance between the two runs' positions step by step, the
  shorter run extended by its last position;
* **boundary accuracy** — share of the surrogate's boundary pairs (:mod:`rapt.boundaries`
  on its labels) whose region the system shares: the system has a boundary pair of the
  same two modes with its midpoint within the surrogate pair's length of the surrogate
  pair's midpoint (the paper's "86.8% of the imitator performance boundary regions were
  the same"); and, stricter, the share across which the system itself changes mode
  (``straddled``: what a confirmation run of both scenarios checks);
* **distance error** — mean over the scenarios of | D_surrogate(x) - D_system(x) |, where
  D is the distance from x to the nearest boundary-pair midpoint of that system's labels;
* **mismatches near a boundary** — share of the scenarios the surrogate gets wrong that
  lie within the 90th percentile pair length of one of the system's boundary midpoints;
* **per boundary type** (:func:`boundary_types`): *recall*, the share of the system's
  boundary pairs of that type with both ends labelled right by the surrogate (a
  confirmation run of the pair would show the system's boundary where the surrogate put
  it), and *precision*, the share of the surrogate's pairs of that type whose region the
  system shares.  Mode accuracy hides a surrogate that is right everywhere but at the
  boundaries, and a rare type (a collision) hides inside the overall figures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from rapt.boundaries import boundary_pairs
from rapt.errors import InputError

__all__ = ["Agreement", "agreement", "path_error", "confusion_matrix", "TypeAgreement", "boundary_types"]


def confusion_matrix(truth: np.ndarray, predicted: np.ndarray, n_modes: int) -> np.ndarray:
    """(n_modes, n_modes) counts: rows the true mode, columns the predicted one."""
    out = np.zeros((n_modes, n_modes), dtype=np.int64)
    np.add.at(out, (np.asarray(truth, int), np.asarray(predicted, int)), 1)
    return out


def path_error(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """Mean per-step distance between paired (steps, 2) tracks, the shorter padded with its end."""
    errs = []
    for p, q in zip(a, b):
        if p is None or q is None or not len(p) or not len(q):
            continue
        n = max(len(p), len(q))
        P = np.vstack([p, np.repeat(p[-1:], n - len(p), axis=0)])
        Q = np.vstack([q, np.repeat(q[-1:], n - len(q), axis=0)])
        errs.append(float(np.mean(np.linalg.norm(P - Q, axis=1))))
    return float(np.mean(errs)) if errs else float("nan")


@dataclass
class Agreement:
    n: int
    mode_accuracy: float
    confusion: np.ndarray
    surrogate_pairs: int
    system_pairs: int
    boundary_accuracy: float
    straddled: float
    distance_error: float
    mismatches: int
    mismatches_near_boundary: float


def _midpoints(X: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pairs = boundary_pairs(X, labels=labels)
    return pairs.i, pairs.j, (X[pairs.i] + X[pairs.j]) / 2 if len(pairs) else np.zeros((0, X.shape[1]))


def _shared_regions(X, si, sj, s_mid, s_lab, ti, tj, t_mid, t_lab) -> np.ndarray:
    """Per surrogate pair: a system pair of the same two modes lies within its length."""
    out = np.zeros(si.size, dtype=bool)
    s_type = np.sort(np.column_stack([s_lab[si], s_lab[sj]]), axis=1)
    t_type = np.sort(np.column_stack([t_lab[ti], t_lab[tj]]), axis=1)
    length = np.linalg.norm(X[si] - X[sj], axis=1)
    for a, b in {tuple(t) for t in s_type.tolist()}:
        mine = np.flatnonzero((s_type[:, 0] == a) & (s_type[:, 1] == b))
        theirs = np.flatnonzero((t_type[:, 0] == a) & (t_type[:, 1] == b))
        if theirs.size:
            d, _ = cKDTree(t_mid[theirs]).query(s_mid[mine])
            out[mine] = d <= length[mine]
    return out


def agreement(X: np.ndarray, system: np.ndarray, surrogate: np.ndarray, n_modes: int = 4) -> Agreement:
    """The figures of the module docstring for labels ``system`` and ``surrogate`` at scenarios ``X``."""
    X = np.asarray(X, dtype=float)
    system, surrogate = np.asarray(system, int), np.asarray(surrogate, int)
    if not (X.shape[0] == system.shape[0] == surrogate.shape[0]):
        raise InputError("X, system, surrogate: expected one label per scenario")
    accuracy = float(np.mean(system == surrogate))
    si, sj, s_mid = _midpoints(X, surrogate)
    ti, tj, t_mid = _midpoints(X, system)
    straddled = float(np.mean(system[si] != system[sj])) if si.size else float("nan")
    shared = _shared_regions(X, si, sj, s_mid, surrogate, ti, tj, t_mid, system)
    regions = float(np.mean(shared)) if si.size else float("nan")
    if s_mid.shape[0] and t_mid.shape[0]:
        d_s, _ = cKDTree(s_mid).query(X)
        d_t, _ = cKDTree(t_mid).query(X)
        distance_error = float(np.mean(np.abs(d_s - d_t)))
    else:
        d_t = np.full(X.shape[0], np.inf)
        distance_error = float("nan")
    wrong = np.flatnonzero(system != surrogate)
    if wrong.size and ti.size:
        radius = np.quantile(np.linalg.norm(X[ti] - X[tj], axis=1), 0.9)
        near = float(np.mean(d_t[wrong] <= radius))
    else:
        near = float("nan")
    return Agreement(
        int(X.shape[0]),
        accuracy,
        confusion_matrix(system, surrogate, n_modes),
        int(si.size),
        int(ti.size),
        regions,
        straddled,
        distance_error,
        int(wrong.size),
        near,
    )


@dataclass
class TypeAgreement:
    """Recall and precision of one boundary type (``modes`` (a, b), a < b; ``None``: all types)."""

    modes: tuple[int, int] | None
    system_pairs: int
    recall: float  # system pairs of the type with both ends right
    surrogate_pairs: int
    precision: float  # surrogate pairs of the type whose region the system shares


def boundary_types(
    X: np.ndarray, system: np.ndarray, surrogate: np.ndarray, touching: tuple[int, ...] = ()
) -> dict[tuple[int, int] | str, TypeAgreement]:
    """Per boundary type (the sorted pair of modes), recall and precision (module docstring).

    Also ``"all"`` (every pair) and, with ``touching`` modes, ``"touching"``: the pairs with an
    end in one of them (the system's for recall, the surrogate's for precision).
    """
    X = np.asarray(X, dtype=float)
    system, surrogate = np.asarray(system, int), np.asarray(surrogate, int)
    if not (X.shape[0] == system.shape[0] == surrogate.shape[0]):
        raise InputError("X, system, surrogate: expected one label per scenario")
    ti, tj, t_mid = _midpoints(X, system)
    si, sj, s_mid = _midpoints(X, surrogate)
    right = (surrogate[ti] == system[ti]) & (surrogate[tj] == system[tj])
    shared = _shared_regions(X, si, sj, s_mid, surrogate, ti, tj, t_mid, system)
    t_type = np.sort(np.column_stack([system[ti], system[tj]]), axis=1)
    s_type = np.sort(np.column_stack([surrogate[si], surrogate[sj]]), axis=1)

    def one(modes, t_sel: np.ndarray, s_sel: np.ndarray) -> TypeAgreement:
        return TypeAgreement(
            modes,
            int(t_sel.sum()),
            float(np.mean(right[t_sel])) if t_sel.any() else float("nan"),
            int(s_sel.sum()),
            float(np.mean(shared[s_sel])) if s_sel.any() else float("nan"),
        )

    out: dict[tuple[int, int] | str, TypeAgreement] = {}
    kinds = sorted({tuple(t) for t in t_type.tolist()} | {tuple(t) for t in s_type.tolist()})
    for a, b in kinds:
        t_sel = np.asarray((t_type[:, 0] == a) & (t_type[:, 1] == b))
        s_sel = np.asarray((s_type[:, 0] == a) & (s_type[:, 1] == b))
        out[(a, b)] = one((a, b), t_sel, s_sel)
    out["all"] = one(None, np.ones(ti.size, dtype=bool), np.ones(si.size, dtype=bool))
    if touching:
        t_touch = np.asarray(np.isin(t_type, touching).any(axis=1))
        out["touching"] = one(None, t_touch, np.asarray(np.isin(s_type, touching).any(axis=1)))
    return out
