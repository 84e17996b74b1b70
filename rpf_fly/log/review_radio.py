"""The review's radio part: each dongle's measured load over the log (``/radio/<dongle>``; none in older logs)
against what the radio budget planned and what the dongle carries.
"""

from __future__ import annotations

from dataclasses import dataclass

from rpf_fly.log.reader import LogData


@dataclass(frozen=True)
class RadioSummary:
    """One dongle's measured load over the log (``/radio/<dongle>``): packets a second, mean over the windows
    and the busiest window, against what the budget planned and what the dongle carries."""

    dongle: int
    drones: tuple[str, ...]
    windows: int
    packets: float
    seconds: float
    peak_packets_per_s: float
    peak_transactions_per_s: float
    planned_per_s: float
    budget_per_s: float
    setpoints_superseded: float = 0.0

    @property
    def mean_packets_per_s(self) -> float:
        return self.packets / self.seconds if self.seconds > 0 else 0.0

    def line(self) -> str:
        """``rpf-fly review``'s line for this dongle."""
        use = self.peak_packets_per_s / self.budget_per_s if self.budget_per_s > 0 else 0.0
        over = "  OVER BUDGET" if self.peak_packets_per_s > self.budget_per_s > 0 else ""
        lag = (
            f"; {self.setpoints_superseded:.0f} setpoints superseded before the radio took them (it lagged)"
            if self.setpoints_superseded >= 0.5
            else ""
        )
        return (
            f"radio dongle {self.dongle} ({len(self.drones)} drones): {self.peak_packets_per_s:.0f} packets/s "
            f"in the busiest second, {self.mean_packets_per_s:.0f} on average; planned "
            f"{self.planned_per_s:.0f}, budget {self.budget_per_s:.0f} ({use:.0%}); air in use "
            f"{self.peak_transactions_per_s:.0f} transactions/s at most (polls included){lag}{over}"
        )


def radio_of(data: LogData) -> list[RadioSummary]:
    """Every dongle of the log's ``/radio/<dongle>`` topics, in dongle order ([] for older logs without them)."""
    out = []
    for topic in data.topics:
        if not topic.startswith("/radio/"):
            continue
        msgs = [m.data for m in data.messages(topic)]
        if not msgs:
            continue
        last = msgs[-1]
        out.append(
            RadioSummary(
                int(last.get("dongle", 0)),
                tuple(last.get("drones", ())),
                len(msgs),
                sum(float(m.get("packets", 0.0)) for m in msgs),
                sum(float(m.get("window_s", 0.0)) for m in msgs),
                max(float(m.get("packets_per_s", 0.0)) for m in msgs),
                max(float(m.get("transactions_per_s", 0.0)) for m in msgs),
                float(last.get("planned_per_s", 0.0)),
                float(last.get("budget_per_s", 0.0)),
                sum(float(m.get("setpoints_superseded", 0.0)) for m in msgs),
            )
        )
    return sorted(out, key=lambda r: r.dongle)
