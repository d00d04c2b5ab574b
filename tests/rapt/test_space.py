"""State spaces: the unit cube's mapping to continuous, integer, categorical and permutation parameters, and back."""

import numpy as np
import pytest

from rapt.space import Categorical, Continuous, Integer, Permutation, StateSpace, parameter_from_mapping


def uuv_like_space():
    return StateSpace(
        [
            Continuous("start_time_h", 0.0, 12.0),
            Integer("battery_pct", 60, 100),
            Categorical("sea_state", ("calm", "moderate", "rough")),
            Permutation("area_priority", ("A", "B", "C")),
            Continuous("window_min", 1.0, 100.0, log=True),
        ]
    )


def test_dim_counts_permutation_keys():
    space = uuv_like_space()
    assert space.dim == 1 + 1 + 1 + 3 + 1
    assert space.slice_of("area_priority") == slice(3, 6)


def test_decode_maps_cube_corners_and_slices():
    space = uuv_like_space()
    U = np.array(
        [
            [0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 0.0],
            [1.0, 1.0, 1.0, 0.9, 0.5, 0.1, 1.0],
            [0.5, 0.5, 0.5, 0.5, 0.6, 0.4, 0.5],
        ]
    )
    s = space.decode(U)
    assert s[0] == {
        "start_time_h": 0.0,
        "battery_pct": 60,
        "sea_state": "calm",
        "area_priority": ("A", "B", "C"),
        "window_min": pytest.approx(1.0),
    }
    assert s[1]["start_time_h"] == 12.0 and s[1]["battery_pct"] == 100 and s[1]["sea_state"] == "rough"
    assert s[1]["area_priority"] == ("C", "B", "A")
    assert s[2]["sea_state"] == "moderate"
    assert s[2]["area_priority"] == ("C", "A", "B")
    assert s[2]["window_min"] == pytest.approx(10.0)  # geometric middle of a log range


def test_encode_decode_round_trip():
    space = uuv_like_space()
    rng = np.random.default_rng(3)
    scenarios = space.decode(rng.random((50, space.dim)))
    again = space.decode(space.encode(scenarios))
    for a, b in zip(scenarios, again):
        assert a["battery_pct"] == b["battery_pct"]
        assert a["sea_state"] == b["sea_state"]
        assert a["area_priority"] == b["area_priority"]
        assert a["start_time_h"] == pytest.approx(b["start_time_h"])
        assert a["window_min"] == pytest.approx(b["window_min"])


def test_integer_values_get_equal_slices():
    p = Integer("n", 1, 4)
    u = np.linspace(0, 1, 4001)
    counts = np.bincount(p.from_unit(u) - 1)
    assert counts.tolist() == pytest.approx([1000, 1000, 1000, 1001], abs=1)


def test_from_bounds_and_affine_maps():
    space = StateSpace.from_bounds([(0, 10), (-1, 1)])
    assert space.is_box and space.names == ["x0", "x1"]
    X = space.from_unit_array(np.array([[0.5, 0.25]]))
    assert X.tolist() == [[5.0, -0.5]]
    assert space.to_unit_array(X).tolist() == [[0.5, 0.25]]


@pytest.mark.parametrize(
    "bounds, match",
    [
        ([(1, 1)], "low=1.0 >= high=1.0"),
        ([(2, 1), (0, 1)], "dimension 0"),
        ([(0, np.inf)], "finite"),
        ([1, 2, 3], "pairs"),
    ],
)
def test_bad_bounds_name_the_argument(bounds, match):
    with pytest.raises(ValueError, match="bounds") as err:
        StateSpace.from_bounds(bounds)
    assert match in str(err.value)


def test_bad_parameters():
    with pytest.raises(ValueError, match="'t': low must be < high"):
        Continuous("t", 5, 1)
    with pytest.raises(ValueError, match="unknown type 'angle'"):
        parameter_from_mapping({"name": "a", "type": "angle", "low": 0, "high": 1})
    with pytest.raises(ValueError, match="duplicate names"):
        StateSpace([Continuous("a", 0, 1), Continuous("a", 0, 2)])
    with pytest.raises(ValueError, match="at least 2 choices"):
        Categorical("c", ("only",))
    with pytest.raises(ValueError, match="not an ordering"):
        Permutation("p", ("A", "B")).to_unit([("A", "A")])
    with pytest.raises(ValueError, match="not one of"):
        Categorical("c", ("x", "y")).to_unit(["z"])


def test_snapping_moves_a_scenario_onto_its_resolution_and_a_pair_s_sides_apart():
    p = Continuous("x", 0.05, 0.4, resolution=0.001)
    u = np.linspace(0, 1, 1001)
    assert np.max(np.abs(p.from_unit(u) - (0.05 + u * 0.35))) < 1e-12  # the search stays continuous
    v = p.from_unit(p.snap_unit(u))
    np.testing.assert_array_equal(v, np.round(v, 3))  # on the steps, decoded as the short decimals
    assert v.min() == 0.05 and v.max() == 0.4 and np.max(np.abs(v - (0.05 + u * 0.35))) <= 0.0005 + 1e-12
    # last-digit differences in the cube coordinate do not reach the value
    w = np.random.default_rng(0).random(200)
    t = Continuous("t", 0, 43200, resolution=1.0)
    np.testing.assert_array_equal(t.from_unit(t.snap_unit(w * (1 + 1e-13))), np.round(w * 43200))
    # a pair's sides snap away from each other: they keep the boundary between them
    a, b = t.to_unit(np.array([100.2, 100.7])), t.to_unit(np.array([100.6, 100.3]))
    np.testing.assert_array_equal(t.from_unit(t.snap_unit(a, away_from=b)), [100.0, 101.0])
    np.testing.assert_array_equal(t.from_unit(t.snap_unit(b, away_from=a)), [101.0, 100.0])
    # a space snaps only the parameters with a resolution
    space = StateSpace([t, Continuous("free", 0, 1), Permutation("p", ("A", "B"))])
    U = np.random.default_rng(1).random((4, 4))
    S = space.snap(U)
    np.testing.assert_array_equal(S[:, 1:], U[:, 1:])
    assert all(d["t"] == round(d["t"]) for d in space.decode(S))
    for bad in (0, -1, 0.3, True, "1"):
        with pytest.raises(ValueError, match="'x': resolution must be"):
            Continuous("x", 0.0, 0.5, resolution=bad)


def test_parameter_from_mapping_and_config_round_trip():
    space = StateSpace(
        [
            {"name": "t", "type": "continuous", "low": 0, "high": 1},
            {"name": "r", "type": "continuous", "low": 0, "high": 10, "resolution": 0.5},
            {"name": "k", "type": "integer", "low": 0, "high": 3},
            {"name": "c", "type": "categorical", "choices": ["a", "b"]},
            {"name": "p", "type": "permutation", "items": ["x", "y", "z"]},
        ]
    )
    assert StateSpace(space.to_config()) == space
