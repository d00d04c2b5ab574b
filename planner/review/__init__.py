"""Stage 3, review the logs: read them, compare with the plan, fit the execution bias, calibrate, re-plan."""
