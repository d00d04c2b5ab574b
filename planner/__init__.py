"""RAPT's application, laid out by the range day's stages.

:mod:`planner.plan` makes the plan, :mod:`planner.fly` flies it (in the loop or on a vehicle's
MAVLink port), :mod:`planner.review` compares the logs with it; they share only
:mod:`planner.common`. :mod:`planner.selfright` holds the self-righting studies and
:mod:`planner.cli` the ``rapt-plan`` command line over all of them.
"""
