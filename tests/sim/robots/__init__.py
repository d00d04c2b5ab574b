"""Tests of sim/robots/."""
