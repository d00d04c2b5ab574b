"""Software-in-the-loop over real loopback MAVLink and a real Zenoh session."""

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.fly.sil.loop import run_sil

pytestmark = [pytest.mark.slow, pytest.mark.integration]

EXAMPLES = Path(__file__).resolve().parents[4] / "examples"


@pytest.mark.parametrize("name,count", [("range2017", 4), ("imitation7", 6)])
def test_sil_scores_equal_the_batch_simulator(name, count):
    m = sim.uuv.load_mission(EXAMPLES / f"{name}.toml")
    X = np.random.default_rng(11).random((3 * count, m.dim))
    batch = sim.uuv.simulate(m, X)
    rows = np.flatnonzero(batch.valid)[:count]
    assert rows.size == count
    modes = set()
    for i in rows:
        result = run_sil(m, X[i])
        np.testing.assert_array_equal(result.scores, batch.scores[i], err_msg=f"{name} scenario {i}")
        assert result.speedup > 10  # lock-step does not wait for the clock (benchmarks/sil.py measures it)
        modes.add(int(batch.modes[i]))
    assert len(modes) >= 2  # not only one kind of run
