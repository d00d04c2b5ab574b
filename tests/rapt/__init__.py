"""Tests of rapt/."""
