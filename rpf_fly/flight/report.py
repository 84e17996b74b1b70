"""How a flight went: the loop's timing statistics and the report :meth:`FlightLoop.run` returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rpf_fly.flight.events import FlightEvent
from rpf_fly.flight.gc_pacing import GcStats
from rpf_fly.flight.phases import FlightOutcome, SwarmPhase


@dataclass
class LoopStats:
    """Timing of the flying phase: tick intervals, overruns, planner time per drone, and the latency from a mocap
    frame's receipt to each setpoint handed to the backend (seconds) at the ticks fired by a frame. Ticks fired
    without a frame (mocap late, lost, or slower than the planning rate) are counted in ``frameless_ticks``."""

    ticks: int = 0
    overruns: int = 0
    frameless_ticks: int = 0
    tick_intervals: list[float] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)
    planner_seconds: list[float] = field(default_factory=list)
    gc: GcStats = field(default_factory=GcStats)
    """The garbage collections the loop ran in its gaps (flight/gc_pacing.py)."""

    def summary(self) -> dict[str, float | None]:
        def pct(values: list[float], q: float) -> float | None:
            return float(np.percentile(values, q)) if values else None

        intervals = self.tick_intervals
        median_interval = float(np.median(intervals)) if intervals else 0.0
        return {
            "ticks": self.ticks,
            "overruns": self.overruns,
            "frameless_ticks": self.frameless_ticks,
            "tick_interval_p50_s": pct(intervals, 50),
            "tick_jitter_p99_s": pct([abs(i - median_interval) for i in intervals], 99),
            "tick_interval_max_s": max(intervals) if intervals else None,
            "latency_p50_s": pct(self.latencies, 50),
            "latency_p99_s": pct(self.latencies, 99),
            "latency_max_s": max(self.latencies) if self.latencies else None,
            "planner_p50_s": pct(self.planner_seconds, 50),
            "gc_collections": sum(self.gc.collections),
            "gc_seconds": sum(self.gc.seconds),
        }


@dataclass
class FlightReport:
    """How the flight ended."""

    mission: str
    phase: SwarmPhase
    outcomes: dict[str, FlightOutcome]
    reasons: dict[str, str]
    events: list[FlightEvent]
    stats: LoopStats
    interrupted: bool = False
    error: str | None = None
    log_dropped: int = 0
    """Messages the flight log dropped (queue full, or logged after close)."""
    log_failed: int = 0
    """Messages the flight log could not encode (a schema or value error)."""
    host_behind_s: float | None = None
    """A dry run's or lab's: seconds during this flight that the host let the simulated world run behind its own
    time (`rpf_fly.emulator.host_lag`); None for a real flight. Over 0, the flight's verdict is not evidence."""

    @property
    def host_sentence(self) -> str:
        """The command's last line when the host could not keep up ('' when it did, or for a real flight)."""
        from rpf_fly.emulator.host_lag import HOST_BEHIND_REPORT_S, HOST_LATE_BOUND_S, LATE_WHAT

        if not self.host_behind_s or self.host_behind_s < HOST_BEHIND_REPORT_S:
            return ""

        return (
            f"the host could not keep up for {self.host_behind_s:.1f} s ({LATE_WHAT} more "
            f"than {HOST_LATE_BOUND_S * 1000:.0f} ms late): this dry run is not evidence"
        )

    @property
    def success(self) -> bool:
        return (
            self.error is None
            and not self.interrupted
            and all(o == FlightOutcome.REACHED for o in self.outcomes.values())
        )
