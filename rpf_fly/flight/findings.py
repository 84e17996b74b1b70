"""What a supervisor check found and the response it asks of the flight loop."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Response = Literal["warn", "hold", "land", "lost", "resume", "crashed", "stop"]


@dataclass(frozen=True)
class Finding:
    """What the supervisor saw and what to do: ``response`` for ``drone`` (None: the whole swarm)."""

    kind: str
    level: int
    message: str
    drone: str | None
    response: Response
    land_s: float | None = None
    """For ``land``: how long the landing takes (None: the mission's ``land_s``)."""
