"""Fixtures of the flight tests (the harness is flight_harness.py)."""

import pytest
from flight_harness import SHORT_MISSION

from rpf_fly.mission import parse_mission


@pytest.fixture
def short_mission():
    return parse_mission(SHORT_MISSION)
