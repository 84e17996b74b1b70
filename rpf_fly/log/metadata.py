"""The log's metadata records: the ``mission`` record (name, YAML, version, planner, policy hash, seed, source) and
the ``scenario`` record the review scores a run from (docs/log-format.md, "Metadata").
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any


def obstacle_dict(shape: Any) -> dict[str, Any]:
    """A mission obstacle (``CircleObstacle`` / ``BoxObstacle``) as the log writes it: ``{shape: circle, center,
    radius}`` or ``{shape: box, min, max}`` (the ``scenario`` record, ``FlightLog.scene``)."""
    if getattr(shape, "shape", None) == "circle":
        return {"shape": "circle", "center": [float(v) for v in shape.center], "radius": float(shape.radius)}
    return {"shape": "box", "min": [float(v) for v in shape.min], "max": [float(v) for v in shape.max]}


def file_sha256(path: str | Path | None) -> str:
    """Hex SHA-256 of a file ("" for None)."""
    if path is None:
        return ""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def mission_metadata(
    mission: Any, seed: int = 0, source: str = "flight", dynamics: str | None = None
) -> dict[str, str]:
    """The ``mission`` metadata record of a :class:`~rpf_fly.mission.Mission` (string values). A dry run's or a
    lab's record adds ``dynamics``: the model its simulated drones flew (``dynamics``, else the mission's
    ``dry_run.dynamics``), so a reader need not know which default the writing version had."""
    from rpf_fly import __version__

    extra = {}
    if source in ("dry-run", "lab"):
        extra["dynamics"] = (dynamics or mission.dry_run.dynamics).replace("_", "-")
    return {
        "name": mission.name,
        "yaml": mission.text,
        "rpf_fly_version": __version__,
        "planner": mission.planner.kind,
        "policy_sha256": file_sha256(mission.planner.policy),
        "seed": str(int(seed)),
        "source": source,
        **extra,
    }


def scenario_metadata(mission: Any, scenario: Any = None) -> dict[str, str]:
    """The ``scenario`` metadata record: everything the review needs to score the run, as one JSON string.

    ``scenario`` (a :class:`~rpf_fly.sim.Scenario`) gives the actual (jittered) starts and goals; without it the
    mission's nominal layout is used (a flight)."""
    if scenario is not None:
        names = list(scenario.names)
        starts = [[float(p.real), float(p.imag)] for p in scenario.starts]
        goals = [[float(p.real), float(p.imag)] for p in scenario.goals]
        shapes = scenario.shapes
        ax, ay = scenario.arena_x, scenario.arena_y
    else:
        names = [d.name for d in mission.drones]
        starts = [[float(v) for v in d.start] for d in mission.drones]
        goals = [[float(v) for v in d.goal] for d in mission.drones]
        shapes = mission.obstacles
        ax, ay = mission.arena.x, mission.arena.y
    body = {
        "names": names,
        "starts": starts,
        "goals": goals,
        "obstacles": [obstacle_dict(s) for s in shapes],
        "arena": {"x": [float(v) for v in ax], "y": [float(v) for v in ay], "z": [float(v) for v in mission.arena.z]},
        "dt": float(mission.flight.dt),
        "goal_tolerance": float(mission.flight.goal_tolerance),
        "safety_radius": float(mission.planner.safety_radius),
        "margin": float(mission.planner.margin_m),
        "speed": float(mission.flight.speed),
        "height": float(mission.flight.height),
    }
    return {"json": json.dumps(body)}
