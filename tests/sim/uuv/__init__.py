"""Tests of sim/uuv/."""
