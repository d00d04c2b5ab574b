"""Table 5.1's PRM baseline: the linear local planner finds the nodes Gabriel clustering finds, from the same states."""

from __future__ import annotations

import numpy as np
import pytest

from planner.selfright.analysis import analyse
from planner.selfright.prm import prm_connect, same_graph
from planner.selfright.search import adaptive_study
from sim.robots import load_robot


@pytest.fixture(scope="module")
def one_dof():
    robot = load_robot("examples/robots/1dof.toml")
    study = adaptive_study(robot, 20.0, 700, seed=0, r_min_deg=0.5)
    return study, analyse(study)


def test_prm_builds_the_gabriel_graph_of_the_one_dof_robot(one_dof):
    study, result = one_dof
    prm = prm_connect(study, result, step_deg=3.0)
    # some candidate pairs cross an unstable band or another face, and the planner refuses them
    assert 0 < prm.edges_connected < prm.edges_checked
    assert np.all((prm.labels >= 0) == (result.graph.labels >= 0))
    agreement = same_graph(result, study, prm)
    assert agreement.same and agreement.nodes_matched == 5 and agreement.edges_matched == 7
    assert agreement.states_agreeing == 1.0


def test_checking_coarse_steps_first_changes_nothing_but_the_work(one_dof):
    study, result = one_dof
    fast, full = (prm_connect(study, result, step_deg=3.0, early_exit=e) for e in (True, False))
    assert fast.edges_connected == full.edges_connected
    assert np.array_equal(fast.labels, full.labels)
    assert full.evaluations == full.path_states and fast.path_states == full.path_states
