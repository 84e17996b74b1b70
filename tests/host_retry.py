"""Flying again a shared test flight that the host held back, as the fault campaign flies again a run whose host
fell behind (rpf_fly/campaign/runner.py): used by the CLI flights (tests/conftest.py) and the in-process ones
(tests/flight/flight_harness.py)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

STARVED_KINDS = ("loop", "host", "mocap_late")
"""The flight's own events that say the host held a fault-free dry run back: its loop late or stalled between two
ticks, the simulated world behind its time (`rpf_fly.flight.host_watch`), no mocap frame for 0.1 s (the emulated
Motive and the flight's NatNet client share the host)."""

FlightT = TypeVar("FlightT")

CALM_IDLE = 0.35
"""The share of the host's CPU time idle over a second from which a flight that the host held back is flown again:
with a third of the cores free a dry run keeps its time (the suite's first minutes, its longest flights started
together on every worker, leave none)."""
CALM_WAIT_S = 30.0
"""How long a flight to be flown again waits for a calm host at most (then it flies anyway)."""


def _cpu_times() -> tuple[float, float] | None:
    """(idle, total) jiffies of the host since boot from /proc/stat; None where there is none."""
    try:
        with open("/proc/stat") as stat:
            fields = [float(x) for x in stat.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return fields[3] + (fields[4] if len(fields) > 4 else 0.0), sum(fields)


def wait_for_a_calm_host(wait_s: float = CALM_WAIT_S, idle: float = CALM_IDLE) -> float:
    """Wait until the host was at least ``idle`` idle over a second, for ``wait_s`` at most; the seconds waited.
    Without /proc/stat: a fixed 20 s, as the fault campaign waits before it flies a run again."""
    began = time.monotonic()
    last = _cpu_times()
    if last is None:
        time.sleep(min(20.0, wait_s))
        return time.monotonic() - began
    while time.monotonic() - began < wait_s:
        time.sleep(1.0)
        now = _cpu_times()
        if now is None:
            break
        spent = now[1] - last[1]
        if spent > 0 and (now[0] - last[0]) / spent >= idle:
            break
        last = now
    return time.monotonic() - began


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
