"""The segment fit's batched trials: one replay of the segments repeated per trial equals each trial's own.

The calibration's Jacobian evaluates every finite-difference trial in one replay
(:func:`planner.review.segment_fit.stacked_trials`); a trial replayed in a batch must fly exactly
as it does alone, whichever fields differ between trials: scalar terms, a speed curve's knots,
a vector loop's slow part, or the water.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.review.calibration_terms import knot_name, with_terms
from planner.review.segment_fit import residual_parts, stacked_trials
from planner.review.segments import segment_batch
from sim.uuv.scenario import make_scenarios
from tests.support.simlogs import sim_runs

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"


@pytest.fixture(scope="module")
def segments():
    mission = sim.uuv.load_mission(MISSION)
    X = np.random.default_rng(5).random((6, mission.dim))
    U = X[make_scenarios(mission, X).valid][:2]
    runs = sim_runs(mission, U)
    return mission, segment_batch(mission, runs, list(make_scenarios(mission, U).start_time))


TRIALS = {
    "scalar terms": [
        {"max_turn_rate_dps": 9.0, "hotel_w": 40.0},
        {"max_turn_rate_dps": 14.0, "hotel_w": 40.0},
        {"max_turn_rate_dps": 9.0, "hotel_w": 55.0, "surface_power_w": 20.0},
    ],
    "knots and water": [
        {knot_name(1.0): 0.9, knot_name(2.0): 1.7, "water.current_scale": 1.0},
        {knot_name(1.0): 0.8, knot_name(2.0): 1.9, "water.current_scale": 1.0},
        {knot_name(1.0): 0.9, knot_name(2.0): 1.7, "water.current_scale": 0.5},
    ],
}


@pytest.mark.parametrize("loop", ["surge", "vector"])
@pytest.mark.parametrize("kind", sorted(TRIALS))
def test_a_trial_replayed_in_a_batch_flies_as_it_does_alone(segments, kind, loop):
    mission, seg = segments
    base = dataclasses.replace(mission.vehicle, velocity_control=loop, slow_share=0.3 if loop == "vector" else 0.0)
    trials = [
        dict(t, **({"slow_share": 0.2 + 0.1 * i} if loop == "vector" else {})) for i, t in enumerate(TRIALS[kind])
    ]
    terms = [with_terms(base, t) for t in trials]
    n = seg.valid.shape[0]
    spec, water = stacked_trials(terms, n)
    batched = [r.reshape(len(trials), -1) for r in residual_parts(mission, seg.repeated(len(trials)), spec, water)]
    for i, (vehicle, w) in enumerate(terms):
        alone = residual_parts(mission, seg, vehicle, w)
        for b, a in zip(batched, alone):
            np.testing.assert_allclose(b[i], a, rtol=0, atol=1e-9)
    # and the trials do differ: the batch is not one trial copied
    assert any(np.abs(b[0] - b[1]).max() > 1e-3 for b in batched)
