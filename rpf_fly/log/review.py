"""Review of a flight log: what is in it, how well it was recorded, how well the swarm flew (docs/log-format.md).

This module puts the review together (:func:`review`) and judges the recording: per topic the message count, mean
rate, gaps (intervals longer than three times the topic's median period; not for ``/events`` and ``/scene``, which
have no rate) and messages missing from the sequence, events by level, whether the log ends as a finished run ends
and what interrupted it. Its other parts: the run's layout (rpf_fly/log/review_scenario.py), the metrics JSON of
docs/metrics.md (review_metrics.py), the time series (review_series.py), setpoint tracking against the drones' lag
(review_tracking.py), the radio load (review_radio.py), the CSV export (review_csv.py).

Computation only; :mod:`rpf_fly.log.review_plot` draws. The time axis of the review is the log time minus the
first log time of the file (seconds): every topic is on the recorder's clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from rpf_fly.log.foxglove_schemas import LOG_LEVELS
from rpf_fly.log.reader import LogData
from rpf_fly.log.review_csv import export_csv  # noqa: F401 (rpf_fly/cli/review_cmd.py imports it from here)
from rpf_fly.log.review_metrics import metrics_of
from rpf_fly.log.review_radio import RadioSummary, radio_of
from rpf_fly.log.review_scenario import ReviewError, drones_of, scenario_of
from rpf_fly.log.review_series import battery_series, rms_max, tracking_error
from rpf_fly.log.review_tracking import (
    CRAZYFLIE_LAG_S,
    TrackingExpectation,
    logged_dynamics,
    tracking_expectation,
    tracking_lag,
)
from rpf_fly.sim.metrics import Metrics

GAP_FACTOR = 3.0
"""An interval longer than this many median periods is a gap."""

APERIODIC = ("foxglove.Log", "foxglove.SceneUpdate")
"""Schemas of topics written when something happens, not at a rate: no gap analysis."""


@dataclass(frozen=True)
class TopicStats:
    """One topic's recording quality. Times in seconds from the start of the log."""

    topic: str
    schema: str
    count: int
    rate_hz: float | None
    median_period_s: float | None
    gaps: tuple[tuple[float, float], ...]
    missing: int

    @property
    def longest_gap_s(self) -> float | None:
        return max((g[1] for g in self.gaps), default=None)


class ReviewEvent(NamedTuple):
    """One ``/events`` message: seconds from the start of the log, level (1 debug .. 5 fatal), message, who (a drone,
    ``flight`` or ``sim``) and kind (the flight event's kind, ``phase``, ``interrupt``, ``error``, ...; the
    ``foxglove.Log`` ``file`` field, empty in logs that have none)."""

    t_s: float
    level: int
    message: str
    name: str
    kind: str = ""


@dataclass(frozen=True)
class Interruption:
    """Why a flight did not end as planned: ``signal`` (Ctrl-C, SIGTERM, a KeyboardInterrupt: every drone landed),
    ``error`` (an exception in the flight loop: every drone landed) or ``killed`` (the recording process died: the
    log ends before its footer, or a salvaged copy without the flight's clean end)."""

    how: str
    t_s: float | None
    message: str

    def to_json_dict(self) -> dict[str, Any]:
        return {"how": self.how, "t_s": self.t_s, "message": self.message}


@dataclass
class Review:
    """Everything ``rpf-fly review`` shows."""

    path: Path
    truncated: bool
    start_ns: int
    duration_s: float
    drones: list[str]
    mission: str
    planner: str
    seed: int | None
    topics: list[TopicStats]
    events_by_level: dict[str, int]
    events: list[ReviewEvent]
    metrics: Metrics | None
    metrics_error: str
    scenario: dict[str, Any] | None
    outcomes: dict[str, str | None] = field(default_factory=dict)
    source: str = ""
    """``mission.source`` of the metadata: ``flight``, ``dry-run`` or ``sim`` ("" when the log has none)."""
    clean_end: bool | None = None
    """The recording ended as a finished run ends (a flight: every drone's final status with its outcome; a
    simulation: its end event); None when the log says nothing of its source."""
    interruptions: list[Interruption] = field(default_factory=list)
    tracking: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    """Per drone, and ``all``: RMS and max setpoint tracking error (m); only drones with setpoints and poses."""
    tracking_expected: dict[str, TrackingExpectation] = field(default_factory=dict)
    """Per drone with setpoints and poses (not for a simulation): its tracking error while cruising against what
    its kind of drone gives at the flown speed (:attr:`tracking_lag`)."""
    tracking_lag: tuple[float, str] = (CRAZYFLIE_LAG_S, "Crazyflies with the firmware's default gains")
    """The lag (s) the log's drones trail a moving setpoint by, and what they are (:func:`tracking_lag`)."""
    battery: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    """Per drone with battery telemetry: first, lowest and last voltage (V)."""
    radio: list[RadioSummary] = field(default_factory=list)
    """Per dongle, its measured load (``/radio/<dongle>``; none in older logs)."""

    @property
    def interrupted(self) -> bool:
        return bool(self.interruptions)

    def to_json_dict(self) -> dict[str, Any]:
        """Everything the text summary says: the metrics JSON of docs/metrics.md with its keys where they are (None
        without metrics), extended by the review's own keys (docs/log-format.md, *Review*)."""
        doc: dict[str, Any] = self.metrics.to_json_dict() if self.metrics is not None else {}
        doc.update(
            {
                "log": {
                    "path": str(self.path),
                    "source": self.source,
                    "duration_s": self.duration_s,
                    "truncated": self.truncated,
                    "clean_end": self.clean_end,
                    "start_ns": self.start_ns,
                },
                "interrupted": self.interrupted,
                "interruptions": [i.to_json_dict() for i in self.interruptions],
                "outcomes": dict(self.outcomes),
                "topics": [
                    {
                        "topic": t.topic,
                        "schema": t.schema,
                        "messages": t.count,
                        "rate_hz": t.rate_hz,
                        "gaps": len(t.gaps),
                        "longest_gap_s": t.longest_gap_s,
                        "missing": t.missing,
                    }
                    for t in self.topics
                ],
                "events": {
                    "by_level": dict(self.events_by_level),
                    "warnings": [
                        {
                            "t_s": e.t_s,
                            "level": LOG_LEVELS.get(e.level, str(e.level)),
                            "kind": e.kind,
                            "name": e.name,
                            "message": e.message,
                        }
                        for e in self.events
                        if e.level >= 3
                    ],
                },
                "tracking": {name: {"rms_m": rms, "max_m": peak} for name, (rms, peak) in self.tracking.items()},
                "tracking_expected": self.tracking_expected_json(),
                "battery": {name: {"first_v": a, "min_v": b, "last_v": c} for name, (a, b, c) in self.battery.items()},
                "radio": {
                    str(r.dongle): {
                        "drones": list(r.drones),
                        "windows": r.windows,
                        "mean_packets_per_s": r.mean_packets_per_s,
                        "peak_packets_per_s": r.peak_packets_per_s,
                        "peak_transactions_per_s": r.peak_transactions_per_s,
                        "planned_per_s": r.planned_per_s,
                        "budget_per_s": r.budget_per_s,
                        "setpoints_superseded": r.setpoints_superseded,
                    }
                    for r in self.radio
                },
            }
        )
        if self.metrics is None:
            doc["metrics_error"] = self.metrics_error
        return doc

    def tracking_expected_json(self) -> dict[str, Any]:
        """``{lag_s, drones, per_drone: {drone: TrackingExpectation.to_json_dict()}}``; ``{}`` without any."""
        if not self.tracking_expected:
            return {}
        lag_s, who = self.tracking_lag
        return {
            "lag_s": lag_s,
            "drones": who,
            "per_drone": {name: e.to_json_dict() for name, e in self.tracking_expected.items()},
        }


def topic_stats(data: LogData, topic: str, start_ns: int) -> TopicStats:
    """Count, rate, gaps (> ``GAP_FACTOR`` median periods, on log time) and sequence numbers missing."""
    msgs = data.messages(topic)
    count = len(msgs)
    rate = median = None
    gaps: list[tuple[float, float]] = []
    missing = 0
    if count >= 2:
        t = np.array([m.log_time for m in msgs], dtype=np.int64)
        span = (t[-1] - t[0]) / 1e9
        rate = (count - 1) / span if span > 0 else None
        periods = np.diff(t) / 1e9
        positive = periods[periods > 0]
        if count >= 3 and positive.size and data.schemas.get(topic) not in APERIODIC:
            median = float(np.median(positive))
            for k in np.flatnonzero(periods > GAP_FACTOR * median):
                gaps.append(((t[k] - start_ns) / 1e9, float(periods[k])))
    if count:
        seqs = {m.sequence for m in msgs}
        missing = max(seqs) + 1 - len(seqs)
    return TopicStats(topic, data.schemas.get(topic, ""), count, rate, median, tuple(gaps), missing)


def review(data: LogData) -> Review:
    """The review of a log (metrics are None with ``metrics_error`` set when the log cannot give them)."""
    start = data.start_ns or 0
    end = data.end_ns or start
    mission = data.metadata.get("mission", {})
    try:
        scenario: dict[str, Any] | None = scenario_of(data)
    except ReviewError:
        scenario = None
    metrics = None
    error = ""
    try:
        metrics = metrics_of(data)
    except ReviewError as err:
        error = str(err)
    events = [
        ReviewEvent(
            (m.log_time - start) / 1e9,
            int(m.data.get("level", 0)),
            str(m.data.get("message", "")),
            str(m.data.get("name", "")),
            str(m.data.get("file", "") or ""),
        )
        for m in data.messages("/events")
    ]
    by_level = {name: 0 for name in LOG_LEVELS.values()}
    for event in events:
        key = LOG_LEVELS.get(event.level, "unknown")
        by_level[key] = by_level.get(key, 0) + 1
    drones = drones_of(data)
    outcomes: dict[str, str | None] = {}
    for name in drones:
        found = [m.data.get("outcome") for m in data.messages(f"/{name}/status") if m.data.get("outcome")]
        outcomes[name] = found[-1] if found else None
    try:
        seed: int | None = int(mission["seed"])
    except (KeyError, ValueError):
        seed = None
    source = str(mission.get("source", ""))
    clean = clean_end(data, drones, source, events)
    tracking: dict[str, tuple[float | None, float | None]] = {}
    errors = []
    for name in drones:
        e = tracking_error(data, name, start)
        if e.t.size:
            tracking[name] = rms_max(e.values)
            errors.append(e.values)
    if errors:
        tracking["all"] = rms_max(np.concatenate(errors))
    expected = {}
    lag = tracking_lag(source, logged_dynamics(mission))
    if source != "sim":  # a simulation's setpoint is one planning step ahead by construction: no drone trails it
        lag_s = lag[0]
        expected = {name: tracking_expectation(data, name, start, lag_s) for name in tracking if name != "all"}
    battery = {}
    for name in drones:
        b = battery_series(data, name, start)
        if b.t.size:
            battery[name] = (float(b.values[0]), float(b.values.min()), float(b.values[-1]))
    return Review(
        path=data.path,
        truncated=data.truncated,
        start_ns=start,
        duration_s=(end - start) / 1e9,
        drones=drones,
        mission=mission.get("name", ""),
        planner=mission.get("planner", ""),
        seed=seed,
        topics=[topic_stats(data, topic, start) for topic in sorted(data.topics)],
        events_by_level=by_level,
        events=events,
        metrics=metrics,
        metrics_error=error,
        scenario=scenario,
        outcomes=outcomes,
        source=source,
        clean_end=clean,
        interruptions=interruptions_of(data, events, clean, (end - start) / 1e9),
        tracking=tracking,
        tracking_expected=expected,
        tracking_lag=lag,
        battery=battery,
        radio=radio_of(data),
    )


FLIGHT_SOURCES = ("flight", "dry-run")


def clean_end(data: LogData, drones: list[str], source: str, events: list[ReviewEvent]) -> bool | None:
    """Whether the log ends as a finished run ends: a flight's last status of every drone carries its outcome
    (written after every drone is down, right before the log is closed); a simulation has its ``sim end`` event.
    None for a log that does not say what wrote it."""
    if data.truncated:
        return False
    if source in FLIGHT_SOURCES:
        for name in drones:
            statuses = data.messages(f"/{name}/status")
            if not statuses or not statuses[-1].data.get("outcome"):
                return False
        return True
    if source == "sim":
        return any(e.name == "sim" and e.message.startswith("sim end") for e in events)
    return None


def interruptions_of(
    data: LogData, events: list[ReviewEvent], clean: bool | None, duration_s: float
) -> list[Interruption]:
    """What interrupted the flight, in time order: the flight's ``interrupt`` events (a signal or a
    KeyboardInterrupt), its ``flight loop failed`` errors, and a log without a clean end (a kill)."""
    found = []
    for e in events:
        if e.kind == "interrupt":
            found.append(Interruption("signal", e.t_s, e.message))
        elif e.kind == "error" and e.level >= 5 and e.message.startswith("flight loop failed"):
            found.append(Interruption("error", e.t_s, e.message))
    if data.truncated:
        found.append(
            Interruption(
                "killed",
                duration_s,
                "the log ends before its footer: the recording process was "
                "killed (SIGKILL, a crash, power lost); `--salvage` writes a "
                "finished copy",
            )
        )
    elif clean is False:
        found.append(
            Interruption(
                "killed",
                duration_s,
                "the log has no clean end (the drones' final status is "
                "missing): the recording process was killed; this is a "
                "salvaged or cut copy",
            )
        )
    return found
