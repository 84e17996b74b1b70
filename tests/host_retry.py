"""Flying again a shared test flight that the host held back, as the fault campaign flies again a run whose host
fell behind (rpf_fly/campaign/runner.py): used by the CLI flights (tests/conftest.py) and the in-process ones
(tests/flight/flight_harness.py)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from rpf_fly.campaign.calm_host import wait_for_a_calm_host

STARVED_KINDS = ("loop", "host", "mocap_late")
"""The flight's own events that say the host held a fault-free dry run back: its loop late or stalled between two
ticks, the simulated world behind its time (`rpf_fly.flight.host_watch`), no mocap frame for 0.1 s (the emulated
Motive and the flight's NatNet client share the host)."""

FlightT = TypeVar("FlightT")


def fly_on_time(
    fly: Callable[[Path], FlightT],
    folder: Path,
    ended_as_needed: Callable[[FlightT], bool],
    held_back: Callable[[FlightT], bool],
    tries: int = 3,
) -> FlightT:
    """``fly(folder)``, flown again in ``folder/again-N`` (up to ``tries`` in all, each once the host is calm:
    `wait_for_a_calm_host`) while a flight did not end as its tests need and its own events say the host held it
    back. One that failed on time is returned at once, and the last try whatever it did: the caller's assertions
    fail on it."""
    flight = fly(folder)
    for again in range(1, tries):
        if ended_as_needed(flight) or not held_back(flight):
            break
        retry = folder / f"again-{again}"
        retry.mkdir()
        waited = wait_for_a_calm_host()
        (retry / "waited-for-the-host.txt").write_text(f"{waited:.1f} s, pid {os.getpid()}\n")
        flight = fly(retry)
    return flight
