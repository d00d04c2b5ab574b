"""Fakes, fixtures and loopback helpers shared by the tests."""
