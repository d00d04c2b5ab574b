"""Fixtures of the bridge tests."""

from __future__ import annotations

import pytest

from tests.support.loopback import no_new_threads


@pytest.fixture(autouse=True)
def no_leftover_threads():
    """Every thread a test starts (bridge, logger, vehicle, collectors) has ended when it returns."""
    with no_new_threads():
        yield
