"""The kit both HTML reports are written with: the plan's ``report.html`` and the comparison's ``comparison.html``.

:mod:`~planner.common.html.text` escapes text and formats numbers for a page;
:mod:`~planner.common.html.figures` draws the reports' PNG figures headless (matplotlib's
Agg backend), saves them and draws the mission areas of a map.  What the two pages write
differently (the dash of a missing value, their stylesheets) stays a parameter or the
report's own.
"""
