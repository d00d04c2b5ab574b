"""Tests of the command line, planner/cli: each command as a user runs it."""
