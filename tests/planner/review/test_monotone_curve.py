"""A calibrated speed curve never falls: a saturated loop's knots that read lower at a higher command are pooled."""

from __future__ import annotations

import pytest

from planner.review.calibration_terms import monotone_curve
from rapt.mapfit import MapEstimate, Prior


def _estimate(values: dict[str, float], stderr: dict[str, float]) -> MapEstimate:
    priors = tuple(Prior(n, v, 1.0, 0.0, 1000.0) for n, v in values.items())
    names = list(values)
    return MapEstimate(priors, dict(values), dict(values), dict(stderr), dict.fromkeys(names, True), {}, 10, True, "")


def test_a_knot_that_falls_is_pooled_with_its_neighbour_by_weight():
    # the firmware's calibration flight measured 2.23 m/s at a 3 m/s command and 1.91 at 3.9 (saturated)
    est = _estimate(
        {
            "speed_curve[1]": 0.99,
            "speed_curve[2]": 1.98,
            "speed_curve[3]": 2.23,
            "speed_curve[3.9]": 1.91,
            "drag_w": 480,
        },
        {"speed_curve[1]": 0.01, "speed_curve[2]": 0.1, "speed_curve[3]": 0.1, "speed_curve[3.9]": 0.2, "drag_w": 9},
    )
    out = monotone_curve(est)
    v = out.value
    pooled = (2.23 / 0.1**2 + 1.91 / 0.2**2) / (1 / 0.1**2 + 1 / 0.2**2)
    assert v["speed_curve[3]"] == pytest.approx(pooled) and v["speed_curve[3.9]"] == pytest.approx(pooled)
    assert [v[f"speed_curve[{c}]"] for c in ("1", "2", "3", "3.9")] == sorted(v[n] for n in v if "curve" in n)
    assert v["speed_curve[1]"] == 0.99 and v["drag_w"] == 480  # the rest untouched
    assert est.value["speed_curve[3.9]"] == 1.91  # the input is not modified


def test_a_rising_curve_is_left_as_it_is():
    est = _estimate({"speed_curve[1]": 1.0, "speed_curve[2]": 1.9}, {"speed_curve[1]": 0.1, "speed_curve[2]": 0.1})
    assert monotone_curve(est).value == est.value
