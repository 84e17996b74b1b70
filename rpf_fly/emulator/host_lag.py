"""How far the host lets the simulated world fall behind its own time.

A dry run or a lab is evidence only while the machine that runs it keeps up: a world step that runs late, or a
mocap frame the emulator sends late, is time the simulated drones did not have (their extpos arrives late, their
estimators drift, their supervisors act on it), and a verdict taken then is the host's, not the stack's. Each
periodic job of the world (the 100 Hz physics step of `rpf_fly.emulator.fake_world.FakeWorld`, the NatNet
emulator's frames) records how late each of its runs starts against its own schedule; a run later than
`HOST_LATE_BOUND_S` counts the wall time until the job is back on schedule as time behind.

The ground station's own side of a dry run is watched the same way where the emulator stands in for hardware in
its process: each fake radio link's transaction (`rpf_fly.emulator.fake_radio`) records the time the host held it
on top of what the radio takes (its thread waking late, the round trip to the world's process), so a flight
process starved between handing a mocap position to cflib and the simulated drone receiving it is named too (its
flight loop may tick on time meanwhile). A link held longer than the bound counts as behind, as a late world step
does (:data:`LINKS`).

The bound: 0.05 s is five world steps and a whole mocap period at 20 Hz. A real Crazyflie's stabilizer runs every
1 ms on its own processor and Motive sends every frame on its own machine; the emulated ones share this host's two
cores with the flight, and a step or frame this late changes what a flight sees (a setpoint watchdog of 0.5 s, a
pose age of 0.25 s, the supervisor's 0.2 s tracking window are 5-10 such delays). A few isolated late steps under
the bound are the host's normal scheduling noise (measured: under 15 ms on an idle 2-core machine).
"""

from __future__ import annotations

import os
import threading
from dataclasses import asdict, dataclass
from typing import Any

HOST_LATE_BOUND_S = 0.05
"""A periodic emulator job that starts later than this against its schedule is behind (module doc)."""

LATE_WHAT = "simulated steps, mocap frames or radio transactions"
"""What the host held back, in the line that says it (`HostLag.sentence`, the flight report's)."""

HOST_BEHIND_REPORT_S = 0.1
"""Time behind, summed over a flight, from which it is said: one step a little over the bound is scheduling noise;
0.1 s behind is two setpoint periods at 20 Hz, a fifth of the setpoint watchdog's first window."""


@dataclass(frozen=True)
class JobLag:
    """One periodic job's lateness so far."""

    runs: int
    late_runs: int
    """Runs that started more than `HOST_LATE_BOUND_S` late."""
    max_late_s: float
    behind_s: float
    """Wall time during which the job ran later than the bound."""


@dataclass(frozen=True)
class HostLag:
    """What the host did to the simulated world's time (`LagMeter.report` of each job)."""

    bound_s: float
    world: JobLag
    natnet: JobLag | None
    links: JobLag | None = None
    """The flight process's fake radio links (:data:`LINKS`): None where the world's figures were read alone."""

    @property
    def behind_s(self) -> float:
        """The longest any job of the world was behind: the time this world was not evidence."""
        return max(
            self.world.behind_s,
            self.natnet.behind_s if self.natnet is not None else 0.0,
            self.links.behind_s if self.links is not None else 0.0,
        )

    @property
    def kept_up(self) -> bool:
        return self.behind_s < HOST_BEHIND_REPORT_S

    def as_dict(self) -> dict[str, Any]:
        return {
            "bound_s": self.bound_s,
            "behind_s": self.behind_s,
            "world": asdict(self.world),
            "natnet": asdict(self.natnet) if self.natnet is not None else None,
            "links": asdict(self.links) if self.links is not None else None,
        }

    def sentence(self, since: HostLag | None = None) -> str:
        """The line that says the host fell behind (since ``since``); '' when it kept up."""
        behind = self.behind_since(since)
        if behind < HOST_BEHIND_REPORT_S:
            return ""
        return (
            f"the host could not keep up for {behind:.1f} s ({LATE_WHAT} more than "
            f"{self.bound_s * 1000:.0f} ms late): this dry run is not evidence"
        )

    def behind_since(self, since: HostLag | None = None) -> float:
        """Seconds behind since ``since`` (an earlier reading of the same world; None: since it started): each
        job's own time behind since then, the longest of them (a job's figure only grows)."""
        if since is None:
            return self.behind_s

        def grew(now: JobLag | None, then: JobLag | None) -> float:
            if now is None:
                return 0.0
            return max(0.0, now.behind_s - (then.behind_s if then is not None else 0.0))

        return max(grew(self.world, since.world), grew(self.natnet, since.natnet), grew(self.links, since.links))


class LagMeter:
    """One periodic job's lateness: `record` at the start of each run with how late it is; one writer thread,
    any reader (`snapshot`)."""

    def __init__(self, bound_s: float = HOST_LATE_BOUND_S) -> None:
        self.bound_s = bound_s
        self._lock = threading.Lock()
        self._runs = 0
        self._late_runs = 0
        self._max_late_s = 0.0
        self._behind_s = 0.0
        self._last_s: float | None = None
        self._was_late = False

    def record(self, late_s: float, now_s: float, period_s: float) -> None:
        """A run started at ``now_s`` (any clock in seconds), ``late_s`` after its scheduled time."""
        late = late_s > self.bound_s
        with self._lock:
            self._runs += 1
            self._max_late_s = max(self._max_late_s, late_s)
            if late:
                self._late_runs += 1
                since = now_s - self._last_s if self._was_late and self._last_s is not None else late_s
                self._behind_s += max(0.0, since)
            self._last_s, self._was_late = now_s, late

    def snapshot(self) -> JobLag:
        with self._lock:
            return JobLag(self._runs, self._late_runs, self._max_late_s, self._behind_s)


class SpanMeter:
    """Lateness recorded by many threads at once (each fake link's transaction thread): every record is a span of
    wall time that a run was held (``held_s`` up to ``now_s``), and the time behind is the length of the union of
    the spans longer than the bound, so two links held by the same stall count it once."""

    def __init__(self, bound_s: float = HOST_LATE_BOUND_S) -> None:
        self.bound_s = bound_s
        self.window: tuple[float, float] | None = None
        """When set, (from, to) in ``time.monotonic`` seconds: only the part of each span inside it counts (a
        flight's: its preflight to the end of its landing; connecting and closing hold the links for the flight's
        own reasons, at no cost to what it judges)."""
        self._lock = threading.Lock()
        self._runs = 0
        self._late_runs = 0
        self._max_late_s = 0.0
        self._behind_s = 0.0
        self._covered_to = -float("inf")

    def record(self, held_s: float, now_s: float) -> None:
        """A run ended at ``now_s`` (``time.monotonic``) after the host held it ``held_s``."""
        window = self.window
        if window is not None:
            if now_s < window[0] or now_s - held_s > window[1]:
                return
            start_s, now_s = max(now_s - held_s, window[0]), min(now_s, window[1])
            held_s = max(0.0, now_s - start_s)
        with self._lock:
            self._runs += 1
            self._max_late_s = max(self._max_late_s, held_s)
            if held_s <= self.bound_s:
                return
            self._late_runs += 1
            if now_s > self._covered_to:
                self._behind_s += now_s - max(now_s - held_s, self._covered_to)
                self._covered_to = now_s

    def snapshot(self) -> JobLag:
        with self._lock:
            return JobLag(self._runs, self._late_runs, self._max_late_s, self._behind_s)


LINKS = SpanMeter()
"""This process's fake radio links: the time the host held each transaction beyond the radio's own (module doc).
Process-wide, as the links are; a reader takes differences between two snapshots (`HostLag.behind_since`)."""


WORLD_NICE = -10
"""The scheduling priority the simulated world's process asks for (`ahead_of_the_ground_station`)."""


def ahead_of_the_ground_station() -> bool:
    """Ask the host to schedule this process (the simulated drones and Motive) ahead of the ground station's: a real
    Crazyflie runs its stabilizer on its own processor and Motive on its own machine, so however loaded the laptop
    is, their time does not stretch. Raising the priority needs the right to (root, CAP_SYS_NICE, a raised
    RLIMIT_NICE); without it the world runs at the normal priority and `HostLag` says when that was not enough.
    True if granted."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, WORLD_NICE)
    except (OSError, AttributeError):
        return False
    return True


def host_lag(world: LagMeter, natnet: LagMeter | None) -> HostLag:
    return HostLag(world.bound_s, world.snapshot(), natnet.snapshot() if natnet is not None else None)


def with_links(lag: HostLag, since: JobLag | None = None) -> HostLag:
    """``lag`` (the world's figures, read wherever the world runs) with this process's links' (:data:`LINKS`),
    counted from ``since`` (an earlier snapshot of them; its longest delay is not taken off: a late run's figure)."""
    links = LINKS.snapshot()
    if since is not None:
        links = JobLag(
            links.runs - since.runs,
            links.late_runs - since.late_runs,
            links.max_late_s,
            max(0.0, links.behind_s - since.behind_s),
        )
    return HostLag(lag.bound_s, lag.world, lag.natnet, links)
