"""RAPT's tests, one sub-package per package (rapt, sim, bridge, planner, cli)."""
