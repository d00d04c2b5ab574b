"""``python -m planner.cli``: the same command line as the ``rapt-plan`` script."""

from __future__ import annotations

from planner.cli import rapt_plan

rapt_plan()
