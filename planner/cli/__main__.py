"""``python -m planner.cli``: the same command line as the ``rapt-plan`` script."""

from __future__ import annotations

import sys

from planner.cli import app

sys.exit(app())
