"""What a flight log says of the run it recorded: its ``scenario`` metadata record, its drones, its obstacles.

The review's other parts (rpf_fly/log/review.py, review_metrics.py, review_series.py) read the run's layout from
here; a log without what they need raises :class:`ReviewError`.
"""

from __future__ import annotations

import json
from typing import Any

from rpf_fly.log.reader import LogData


class ReviewError(Exception):
    """The log lacks what a part of the review needs (metadata, planner ticks)."""


def scenario_of(data: LogData) -> dict[str, Any]:
    """The ``scenario`` metadata record, parsed. Raises :class:`ReviewError`."""
    record = data.metadata.get("scenario")
    if record is None or "json" not in record:
        raise ReviewError("no scenario metadata record")
    try:
        scenario = json.loads(record["json"])
    except ValueError as err:
        raise ReviewError(f"scenario metadata is not JSON: {err}") from None
    missing = [k for k in ("names", "goals", "obstacles", "dt", "goal_tolerance", "safety_radius") if k not in scenario]
    if missing:
        raise ReviewError(f"scenario metadata lacks {', '.join(missing)}")
    return scenario


DRONE_PREFIXES = ("mocap", "truth")
"""Topics ``/<prefix>/<drone>``; every other two-part topic is ``/<drone>/<what>`` (but `NOT_DRONE_PREFIXES`)."""

NOT_DRONE_PREFIXES = ("radio",)
"""Two-part topics that name no drone: ``/radio/<dongle>``."""


def drones_of(data: LogData) -> list[str]:
    """Drone names: from the scenario record, else from the topics (``/mocap/<d>``, ``/truth/<d>``,
    ``/<d>/planner``, ...)."""
    try:
        return list(scenario_of(data)["names"])
    except ReviewError:
        pass
    names: list[str] = []
    for topic in data.topics:
        parts = topic.strip("/").split("/")
        if len(parts) != 2:
            continue
        if parts[0] in NOT_DRONE_PREFIXES:
            continue
        name = parts[1] if parts[0] in DRONE_PREFIXES else parts[0]
        if name and name not in names:
            names.append(name)
    return names


def obstacle_set_of(scenario: dict[str, Any]):
    """The planner's obstacle arrays of the scenario record's obstacles."""
    from rpf_fly.mission.model import BoxObstacle, CircleObstacle
    from rpf_fly.sim.scenario import obstacle_set

    shapes: list[CircleObstacle | BoxObstacle] = []
    for o in scenario["obstacles"]:
        if o["shape"] == "circle":
            shapes.append(CircleObstacle(tuple(o["center"]), o["radius"]))
        else:
            shapes.append(BoxObstacle(tuple(o["min"]), tuple(o["max"])))
    return obstacle_set(shapes)
