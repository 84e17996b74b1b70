"""Waiting for a calm host before a dry run is flown again: a run the host held back is no evidence, and flown again
at once on a host still as busy it is held back again (a campaign's lab run, three tries 20 s apart, all behind in a
loaded test suite). Linux's /proc/stat says how idle the host was; elsewhere a fixed wait stands in."""

from __future__ import annotations

import time

CALM_IDLE = 0.35
"""The share of the host's CPU time idle over a second from which a run the host held back is flown again: with a
third of the cores free a dry run keeps its time."""
CALM_WAIT_S = 30.0
"""How long a run to be flown again waits for a calm host at most (then it flies anyway)."""
FIXED_WAIT_S = 20.0
"""The wait where the host cannot say how idle it is (no /proc/stat)."""


def _cpu_times() -> tuple[float, float] | None:
    """(idle, total) jiffies of the host since boot from /proc/stat; None where there is none."""
    try:
        with open("/proc/stat") as stat:
            fields = [float(x) for x in stat.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return fields[3] + (fields[4] if len(fields) > 4 else 0.0), sum(fields)


def wait_for_a_calm_host(wait_s: float = CALM_WAIT_S, idle: float = CALM_IDLE, at_least_s: float = 0.0) -> float:
    """Wait ``at_least_s``, then until the host was at least ``idle`` idle over a second, for ``wait_s`` at most in
    all; the seconds waited. Without /proc/stat: `FIXED_WAIT_S` (at least ``at_least_s``, at most ``wait_s``)."""
    began = time.monotonic()
    time.sleep(max(0.0, min(at_least_s, wait_s)))
    last = _cpu_times()
    if last is None:
        time.sleep(max(0.0, min(max(FIXED_WAIT_S, at_least_s), wait_s) - (time.monotonic() - began)))
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
