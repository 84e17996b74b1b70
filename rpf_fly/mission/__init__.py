"""Mission files: the YAML format (docs/mission-format.md), its validated dataclasses and the loader.

from rpf_fly.mission import load_mission
mission = load_mission("missions/circle-8-r3.yaml")   # or MissionError: "FILE:LINE: FIELD: problem"
"""

import importlib
from typing import Any

from .errors import MissionError
from .model import (
    PLANNER_KINDS,
    POLICY_KINDS,
    Arena,
    BoxObstacle,
    CircleObstacle,
    Drone,
    FlightSettings,
    Formation,
    Mission,
    MocapSettings,
    Obstacle,
    PlannerSettings,
    RadioSettings,
    SafetySettings,
    SimSettings,
    Vec2,
)

__all__ = [
    "MissionError",
    "field_line",
    "load_mission",
    "parse_mission",
    "with_planner",
    "expand_formation",
    "parse_uri",
    "PLANNER_KINDS",
    "POLICY_KINDS",
    "Arena",
    "BoxObstacle",
    "CircleObstacle",
    "Drone",
    "FlightSettings",
    "Formation",
    "Mission",
    "MocapSettings",
    "Obstacle",
    "PlannerSettings",
    "RadioSettings",
    "SafetySettings",
    "SimSettings",
    "Vec2",
]


_LOADER = {
    "expand_formation": "parser",
    "field_line": "load",
    "load_mission": "load",
    "parse_mission": "load",
    "parse_uri": "radio_uri",
    "with_planner": "load",
}
"""The loader's names, by the module of this package that holds each."""


def __getattr__(name: str) -> Any:
    """The loader (numpy, yaml) is imported on first use: the CLI's help reads the planner kinds of ``model``
    without paying for it."""
    if name in _LOADER:
        return getattr(importlib.import_module(f"{__name__}.{_LOADER[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
