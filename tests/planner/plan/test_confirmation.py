"""The expert's confirmation of surrogate pairs: it finds the expert's boundary near a candidate, within budget."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.plan.confirmation import confirm_pairs

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
IMITATION7 = sim.uuv.load_mission(EXAMPLES / "imitation7.toml")
BATTERY = IMITATION7.space.names.index("start_battery")
# obstacles clear of the vehicle's path: the mode turns on the start battery alone (SS below, TS above)
BASE = np.array([0.0, 0.5, 1.0, 0.5, 0.0, 0.9, 0.5])


def _at(battery: float) -> np.ndarray:
    u = BASE.copy()
    u[BATTERY] = battery
    return u


@pytest.fixture(scope="module")
def boundary() -> float:
    """The expert's start-battery boundary on BASE, to 0.0002 of the unit cube (9 expert runs)."""
    lo, hi = 0.1, 0.9
    modes = sim.uuv.simulate(IMITATION7, np.array([_at(lo), _at(hi)])).modes
    assert modes.tolist() == [1, 3]  # SS, TS
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if sim.uuv.simulate(IMITATION7, _at(mid)[None, :]).modes[0] == 1:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@pytest.fixture(scope="module")
def claimed() -> np.ndarray:
    """The scores a candidate claims at its two ends: the expert's deep in SS and deep in TS."""
    return sim.uuv.simulate(IMITATION7, np.array([_at(0.1), _at(0.9)])).scores


@pytest.fixture
def expert_calls(monkeypatch) -> list[np.ndarray]:
    """Every batch the expert simulates (the confirmation's only cost)."""
    calls: list[np.ndarray] = []
    simulate = sim.uuv.simulate

    def counted(mission, X, **kw):
        assert kw.get("surrogate") is None
        calls.append(np.array(X))
        return simulate(mission, X, **kw)

    monkeypatch.setattr(sim.uuv, "simulate", counted)
    return calls


def _candidate(lo: float, hi: float, claimed: np.ndarray) -> dict:
    """A surrogate pair along the battery claiming SS at ``lo`` and TS at ``hi``."""
    return {
        "level": 0,
        "elements": ["mission_success"],
        "modes": ["SS", "TS"],
        "distance": hi - lo,
        "u": [_at(lo), _at(hi)],
        "scores": claimed,
    }


def test_confirmation_finds_the_expert_boundary_off_the_candidate_and_counts_its_runs(boundary, claimed, expert_calls):
    b = boundary
    candidates = [
        _candidate(b - 0.004, b + 0.004, claimed),
        _candidate(b + 0.033, b + 0.043, claimed),
        _candidate(0.88, 0.89, claimed),
    ]
    out = confirm_pairs(IMITATION7, candidates, k=3, budget=100, radius=0.05)
    rows = sum(len(X) for X in expert_calls)
    # straddling: 2 runs; 0.033 off: 2 ends, probes 0.01, 0.02, 0.04 before a, 1 bisection; deep in TS: 2 ends
    # and probes 0.01, 0.02, 0.04, 0.05 (the radius) before a, then rejected
    assert out.runs == rows == 2 + 6 + 6 and len(expert_calls) == 5  # batched: one call per round
    assert (out.candidates, out.examined, len(out.pairs), out.share_confirmed) == (3, 3, 2, pytest.approx(2 / 3))
    as_is, moved = out.pairs
    assert as_is["moved_by"] == 0 and as_is["expert_runs"] == 2 and as_is["distance"] == pytest.approx(0.008)
    assert moved["expert_runs"] == 6 and moved["distance"] <= 0.01 + 1e-12
    lo, hi = (u[BATTERY] for u in moved["u_override"])
    assert lo < b < hi and moved["moved_by"] == pytest.approx(b + 0.038 - 0.5 * (lo + hi))
    assert moved["moved_by"] > 0.02
    for pair in out.pairs:  # the expert itself changes mode across each kept pair
        again = sim.uuv.simulate(IMITATION7, np.array(pair["u_override"]))
        assert again.modes.tolist() == [1, 3] and pair["modes"] == ["SS", "TS"] == pair["surrogate_modes"]
        assert pair["confirmed_by_expert"] and pair["level"] == 0 and pair["elements"] == ["mission_success"]
    # the rejected candidate's runs stay on its line within the radius of its ends
    far = np.vstack(expert_calls)[:rows]
    far = far[np.all(np.delete(far, BATTERY, axis=1) == np.delete(BASE, BATTERY), axis=1)]
    far = far[far[:, BATTERY] > 0.5, BATTERY]
    assert sorted(far.round(6).tolist()) == sorted(np.round([0.83, 0.84, 0.86, 0.87, 0.88, 0.89], 6).tolist())


def test_confirmation_stops_at_its_budget(boundary, claimed, expert_calls):
    b = boundary
    candidates = [_candidate(0.88, 0.89, claimed), _candidate(b + 0.033, b + 0.043, claimed)]
    out = confirm_pairs(IMITATION7, candidates, k=2, budget=7)
    assert out.runs == sum(len(X) for X in expert_calls) <= 7
    assert out.pairs == [] and out.examined == 2  # the budget ran out before either found a boundary
    assert confirm_pairs(IMITATION7, candidates, k=2, budget=1).examined == 0


def test_the_expert_as_its_own_surrogate_confirms_every_candidate_as_is():
    """generate's wiring: candidates from a study's analysis reach the expert with the scores found there."""
    from planner.plan.analysis import analyse, confirm_with_expert, select_pairs
    from planner.plan.generate import GenerateConfig, search_mission

    a = analyse(IMITATION7, search_mission(IMITATION7, GenerateConfig(budget=500, batch_size=250, seed=1)))
    candidates = select_pairs(a, 10)
    out = confirm_with_expert(IMITATION7, a, candidates, k=10, budget=100)
    assert len(candidates) >= 2 and out.examined == len(out.pairs) == len(candidates)
    assert out.runs == 2 * len(candidates) and out.share_confirmed == 1.0
    for pair, cand in zip(out.pairs, candidates):
        assert pair["moved_by"] == 0 and pair["expert_runs"] == 2 and pair["surrogate_modes"] == cand["modes"]
        assert np.array_equal(pair["u_override"], a.X[cand["rows"]]) and pair["distance"] == pytest.approx(
            cand["distance"]
        )
        # the same boundary type: the expert's own shows at the candidate's level
        assert (pair["modes"], pair["level"], pair["elements"]) == (cand["modes"], cand["level"], cand["elements"])
