"""Every plan the suite generates agrees with itself (:func:`planner.common.plan_consistency.plan_contradictions`).

After each test, any ``plan.json`` written or rewritten under the session's temporary
directory since the last look is checked, whichever test, fixture or subprocess wrote it; a
plan that contradicts itself fails the test that was running when it appeared.
"""

from __future__ import annotations

import json
import os

import pytest

from planner.common.plan_consistency import plan_contradictions

_seen: dict[str, float] = {}


def _new_plans(root: str) -> list[str]:
    found = []
    for directory, _, files in os.walk(root):
        if "plan.json" in files:
            path = os.path.join(directory, "plan.json")
            try:
                mtime = os.stat(path).st_mtime_ns
            except OSError:
                continue
            if _seen.get(path) != mtime:
                _seen[path] = mtime
                found.append(path)
    return found


@pytest.fixture(autouse=True)
def _plans_agree_with_themselves(tmp_path_factory):
    yield
    for path in _new_plans(str(tmp_path_factory.getbasetemp())):
        try:
            plan = json.loads(open(path).read())
        except (OSError, ValueError):
            continue  # a test of damaged plans writes them on purpose
        if not isinstance(plan, dict) or "pairs" not in plan or "scenarios" not in plan:
            continue
        problems = plan_contradictions(plan)
        assert not problems, f"{path} contradicts itself: " + "; ".join(problems)


@pytest.fixture(scope="session")
def small_plan_dir(tmp_path_factory):
    """A 2-pair plan of range2017 with its execution noise (:mod:`tests.support.small_plan`), made once a session;
    tests that write into a plan take a copy (:func:`tests.support.small_plan.plan_copy`)."""
    from tests.support.small_plan import small_plan

    return small_plan(tmp_path_factory.mktemp("small_plan") / "plan")
