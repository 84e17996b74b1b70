"""Review of a flight log: what is in it, how well it was recorded, how well the swarm flew (docs/log-format.md).

Computation only; :mod:`rpf_fly.log.review_plot` draws. The time axis of the review is the log time minus the
first log time of the file (seconds): every topic is on the recorder's clock.

- **summary**: duration, drones, per topic the message count, mean rate, gaps (intervals longer than three times
  the topic's median period; not for ``/events`` and ``/scene``, which have no rate) and messages missing from the
  sequence, events by level;
- **metrics**: the metrics JSON of docs/metrics.md, computed by :func:`rpf_fly.sim.metrics.compute_metrics` from the
  positions the planner saw at every tick (``/<drone>/planner``, ticks ``0..T``) and the ``scenario`` metadata
  record, labelled with the ``mission`` record's name, planner kind and seed;
- **series** for the plots: positions and altitude from ``/mocap``, setpoint tracking error (each setpoint against
  the pose interpolated at the setpoint's log time), minimum planar separation over the mocap times of the first
  drone (other drones interpolated), battery and flight states from ``/status``, events from ``/events``;
- **CSV**: one file per topic with flattened columns.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Optional

import numpy as np

from rpf_fly.log.reader import LogData
from rpf_fly.log.foxglove_schemas import LOG_LEVELS
from rpf_fly.sim.metrics import Metrics, compute_metrics

GAP_FACTOR = 3.0
"""An interval longer than this many median periods is a gap."""

APERIODIC = ("foxglove.Log", "foxglove.SceneUpdate")
"""Schemas of topics written when something happens, not at a rate: no gap analysis."""


class ReviewError(Exception):
    """The log lacks what a part of the review needs (metadata, planner ticks)."""


@dataclass(frozen=True)
class TopicStats:
    """One topic's recording quality. Times in seconds from the start of the log."""

    topic: str
    schema: str
    count: int
    rate_hz: Optional[float]
    median_period_s: Optional[float]
    gaps: tuple[tuple[float, float], ...]
    missing: int

    @property
    def longest_gap_s(self) -> Optional[float]:
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
    t_s: Optional[float]
    message: str

    def to_json_dict(self) -> dict[str, Any]:
        return {"how": self.how, "t_s": self.t_s, "message": self.message}


@dataclass
class Series:
    """Time series of one drone (seconds from the start of the log)."""

    t: np.ndarray
    values: np.ndarray


CRAZYFLIE_LAG_S = 0.55
"""How far a Crazyflie with the firmware's default gains trails a moving position setpoint, in seconds of the
setpoint's speed: 0.5 s from the position gain (``posCtlPid.xKp`` 2 /s; the setpoint carries no velocity to feed
forward), plus the velocity error its velocity loop needs to hold the tilt that balances drag. The Crazyflie dynamics
reference (the firmware's control code against the identified Crazyflie 2.1+ body) trails carrots by 16.4 cm at
0.3 m/s, 27.3 cm at 0.5 m/s and 55.6 cm at 1 m/s, and a circle the same. A planner's setpoint stream moves at the
flight's speed, so its tracking error while cruising is mostly this lag, not a fault."""

DRY_RUN_LAG_S = 0.25
"""The dry run's simulated drone: a first-order follower of its position setpoint with a time constant of 0.25 s
(rpf_fly/emulator/fake_vehicle.py ``TRACK_TAU_S``), which trails a moving setpoint by 0.25 s x speed, less than a
Crazyflie (docs/flight.md, *Known gap*)."""

TRACKING_SLACK_M = 0.05
TRACKING_SLACK_FRACTION = 0.3
"""A drone's median tracking error while cruising is *outside* its expectation when it is further from the
expected ``lag x speed`` than the larger of these: 5 cm (a hovering drone's own wander, mocap jitter) and 30 % (the
speed's spread within the window, a lab's other gains, mocap latency)."""

CRUISE_MIN_SPEED_M_S = 0.1
"""A setpoint moving at least this fast (mean over the last two lags) is cruising; hovering, arriving and holding
setpoints are not judged."""


@dataclass(frozen=True)
class TrackingExpectation:
    """One drone's setpoint tracking error while cruising against what its kind of drone gives at the flown speed:
    ``lag_s`` x the setpoint's speed (the mean over the last ``2 lag_s``), medians over the cruising setpoints.
    None where the drone did not cruise long enough to judge (fewer than 5 such setpoints)."""

    drone: str
    lag_s: float
    samples: int
    speed_m_s: Optional[float] = None
    expected_m: Optional[float] = None
    measured_m: Optional[float] = None

    @property
    def band_m(self) -> Optional[tuple[float, float]]:
        """The range of measured errors that is as expected."""
        if self.expected_m is None:
            return None
        slack = max(TRACKING_SLACK_M, TRACKING_SLACK_FRACTION * self.expected_m)
        return max(0.0, self.expected_m - slack), self.expected_m + slack

    @property
    def outside(self) -> bool:
        band = self.band_m
        return band is not None and self.measured_m is not None and not band[0] <= self.measured_m <= band[1]

    def to_json_dict(self) -> dict[str, Any]:
        band = self.band_m
        return {"cruise_samples": self.samples, "speed_m_s": self.speed_m_s, "expected_m": self.expected_m,
                "measured_m": self.measured_m, "low_m": band[0] if band else None,
                "high_m": band[1] if band else None, "outside": self.outside}


def tracking_lag(source: str, dynamics: str = "") -> tuple[float, str]:
    """The lag (s) with which the log's drones trail a moving setpoint, and what those drones are: for a dry run or
    a lab, the simulated drone (its first-order follower, or with ``dynamics`` ``firmware`` the firmware's cascade,
    which trails as a Crazyflie does); a Crazyflie with the firmware's default gains otherwise."""
    if source in ("dry-run", "lab"):
        if dynamics == "firmware":
            return CRAZYFLIE_LAG_S, "the dry run's simulated Crazyflies (the firmware's default gains)"
        return DRY_RUN_LAG_S, "the dry run's simulated drones"
    return CRAZYFLIE_LAG_S, "Crazyflies with the firmware's default gains"


def dry_run_dynamics(mission_yaml: str) -> str:
    """``dry_run.dynamics`` of the logged mission text ("" when it names none or does not read)."""
    import yaml

    try:
        doc = yaml.safe_load(mission_yaml or "") or {}
        value = (doc.get("dry_run") or {}).get("dynamics", "")
    except (yaml.YAMLError, AttributeError):
        return ""
    return value if isinstance(value, str) else ""


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
    seed: Optional[int]
    topics: list[TopicStats]
    events_by_level: dict[str, int]
    events: list[ReviewEvent]
    metrics: Optional[Metrics]
    metrics_error: str
    scenario: Optional[dict[str, Any]]
    outcomes: dict[str, Optional[str]] = field(default_factory=dict)
    source: str = ""
    """``mission.source`` of the metadata: ``flight``, ``dry-run`` or ``sim`` ("" when the log has none)."""
    clean_end: Optional[bool] = None
    """The recording ended as a finished run ends (a flight: every drone's final status with its outcome; a
    simulation: its end event); None when the log says nothing of its source."""
    interruptions: list[Interruption] = field(default_factory=list)
    tracking: dict[str, tuple[Optional[float], Optional[float]]] = field(default_factory=dict)
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
        doc.update({
            "log": {"path": str(self.path), "source": self.source, "duration_s": self.duration_s,
                    "truncated": self.truncated, "clean_end": self.clean_end, "start_ns": self.start_ns},
            "interrupted": self.interrupted,
            "interruptions": [i.to_json_dict() for i in self.interruptions],
            "outcomes": dict(self.outcomes),
            "topics": [
                {"topic": t.topic, "schema": t.schema, "messages": t.count, "rate_hz": t.rate_hz,
                 "gaps": len(t.gaps), "longest_gap_s": t.longest_gap_s, "missing": t.missing}
                for t in self.topics
            ],
            "events": {
                "by_level": dict(self.events_by_level),
                "warnings": [
                    {"t_s": e.t_s, "level": LOG_LEVELS.get(e.level, str(e.level)), "kind": e.kind, "name": e.name,
                     "message": e.message}
                    for e in self.events if e.level >= 3
                ],
            },
            "tracking": {name: {"rms_m": rms, "max_m": peak} for name, (rms, peak) in self.tracking.items()},
            "tracking_expected": self.tracking_expected_json(),
            "battery": {name: {"first_v": a, "min_v": b, "last_v": c} for name, (a, b, c) in self.battery.items()},
            "radio": {str(r.dongle): {"drones": list(r.drones), "windows": r.windows,
                                      "mean_packets_per_s": r.mean_packets_per_s,
                                      "peak_packets_per_s": r.peak_packets_per_s,
                                      "peak_transactions_per_s": r.peak_transactions_per_s,
                                      "planned_per_s": r.planned_per_s, "budget_per_s": r.budget_per_s,
                                      "setpoints_superseded": r.setpoints_superseded}
                      for r in self.radio},
        })
        if self.metrics is None:
            doc["metrics_error"] = self.metrics_error
        return doc

    def tracking_expected_json(self) -> dict[str, Any]:
        """``{lag_s, drones, per_drone: {drone: TrackingExpectation.to_json_dict()}}``; ``{}`` without any."""
        if not self.tracking_expected:
            return {}
        lag_s, who = self.tracking_lag
        return {"lag_s": lag_s, "drones": who,
                "per_drone": {name: e.to_json_dict() for name, e in self.tracking_expected.items()}}


# ---------------------------------------------------------------------------------------------- metadata


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
        lag = (f"; {self.setpoints_superseded:.0f} setpoints superseded before the radio took them (it lagged)"
               if self.setpoints_superseded >= 0.5 else "")
        return (f"radio dongle {self.dongle} ({len(self.drones)} drones): {self.peak_packets_per_s:.0f} packets/s "
                f"in the busiest second, {self.mean_packets_per_s:.0f} on average; planned "
                f"{self.planned_per_s:.0f}, budget {self.budget_per_s:.0f} ({use:.0%}); air in use "
                f"{self.peak_transactions_per_s:.0f} transactions/s at most (polls included){lag}{over}")


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
        out.append(RadioSummary(
            int(last.get("dongle", 0)), tuple(last.get("drones", ())), len(msgs),
            sum(float(m.get("packets", 0.0)) for m in msgs), sum(float(m.get("window_s", 0.0)) for m in msgs),
            max(float(m.get("packets_per_s", 0.0)) for m in msgs),
            max(float(m.get("transactions_per_s", 0.0)) for m in msgs),
            float(last.get("planned_per_s", 0.0)), float(last.get("budget_per_s", 0.0)),
            sum(float(m.get("setpoints_superseded", 0.0)) for m in msgs)))
    return sorted(out, key=lambda r: r.dongle)


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


def obstacle_set_of(scenario: dict[str, Any]):  # type: ignore[no-untyped-def]
    """The planner's obstacle arrays of the scenario record's obstacles."""
    from rpf_fly.mission.model import BoxObstacle, CircleObstacle
    from rpf_fly.sim.scenario import obstacle_set

    shapes = []
    for o in scenario["obstacles"]:
        if o["shape"] == "circle":
            shapes.append(CircleObstacle(tuple(o["center"]), o["radius"]))
        else:
            shapes.append(BoxObstacle(tuple(o["min"]), tuple(o["max"])))
    return obstacle_set(shapes)


# ---------------------------------------------------------------------------------------------- metrics


def planner_positions(data: LogData, names: list[str]) -> np.ndarray:
    """``(T+1, N)`` complex positions the planner used at ticks ``0..T`` (``T+1`` = the ticks every drone has).

    A tick missing for one drone (dropped message) takes that drone's previous position. A drone that never planned
    (it failed its preflight and stayed on the ground while the others flew) stands where mocap first saw it."""
    tracks = []
    for name in names:
        msgs = data.messages(f"/{name}/planner")
        if not msgs:
            seen = data.messages(f"/mocap/{name}")
            if not seen:
                raise ReviewError(f"no planner ticks for {name} (/{name}/planner) and no mocap pose")
            p = seen[0].data["pose"]["position"]
            tracks.append({0: complex(p["x"], p["y"])})
            continue
        ticks = {}
        for m in msgs:
            p = m.data["position"]
            ticks[int(m.data["tick"])] = complex(p["x"], p["y"])
        tracks.append(ticks)
    length = min((max(t) for t in tracks if len(t) > 1), default=0) + 1
    positions = np.empty((length, len(names)), dtype=complex)
    for i, ticks in enumerate(tracks):
        last = ticks[min(ticks)]
        for k in range(length):
            last = ticks.get(k, last)
            positions[k, i] = last
    return positions


def metrics_of(data: LogData) -> Metrics:
    """The metrics JSON of the run (docs/metrics.md). Raises :class:`ReviewError`."""
    scenario = scenario_of(data)
    mission = data.metadata.get("mission", {})
    names = list(scenario["names"])
    positions = planner_positions(data, names)
    goals = np.array([complex(g[0], g[1]) for g in scenario["goals"]])
    try:
        seed = int(mission.get("seed", "0") or 0)
    except ValueError:
        seed = 0
    return compute_metrics(
        positions,
        goals,
        float(scenario["dt"]),
        float(scenario["goal_tolerance"]),
        float(scenario["safety_radius"]),
        obstacle_set_of(scenario),
        names,
        mission=mission.get("name", ""),
        planner=mission.get("planner", ""),
        seed=seed,
        margin=float(scenario.get("margin", 0.0)),  # logs written before planner.margin: none
    )


# ---------------------------------------------------------------------------------------------- summary


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
        scenario: Optional[dict[str, Any]] = scenario_of(data)
    except ReviewError:
        scenario = None
    metrics = None
    error = ""
    try:
        metrics = metrics_of(data)
    except ReviewError as err:
        error = str(err)
    events = [
        ReviewEvent((m.log_time - start) / 1e9, int(m.data.get("level", 0)), str(m.data.get("message", "")),
                    str(m.data.get("name", "")), str(m.data.get("file", "") or ""))
        for m in data.messages("/events")
    ]
    by_level = {name: 0 for name in LOG_LEVELS.values()}
    for event in events:
        key = LOG_LEVELS.get(event.level, "unknown")
        by_level[key] = by_level.get(key, 0) + 1
    drones = drones_of(data)
    outcomes: dict[str, Optional[str]] = {}
    for name in drones:
        found = [m.data.get("outcome") for m in data.messages(f"/{name}/status") if m.data.get("outcome")]
        outcomes[name] = found[-1] if found else None
    try:
        seed: Optional[int] = int(mission["seed"])
    except (KeyError, ValueError):
        seed = None
    source = str(mission.get("source", ""))
    clean = clean_end(data, drones, source, events)
    tracking: dict[str, tuple[Optional[float], Optional[float]]] = {}
    errors = []
    for name in drones:
        e = tracking_error(data, name, start)
        if e.t.size:
            tracking[name] = rms_max(e.values)
            errors.append(e.values)
    if errors:
        tracking["all"] = rms_max(np.concatenate(errors))
    expected = {}
    lag = tracking_lag(source, dry_run_dynamics(str(mission.get("yaml", ""))))
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


def clean_end(data: LogData, drones: list[str], source: str, events: list[ReviewEvent]) -> Optional[bool]:
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


def interruptions_of(data: LogData, events: list[ReviewEvent], clean: Optional[bool],
                     duration_s: float) -> list[Interruption]:
    """What interrupted the flight, in time order: the flight's ``interrupt`` events (a signal or a
    KeyboardInterrupt), its ``flight loop failed`` errors, and a log without a clean end (a kill)."""
    found = []
    for e in events:
        if e.kind == "interrupt":
            found.append(Interruption("signal", e.t_s, e.message))
        elif e.kind == "error" and e.level >= 5 and e.message.startswith("flight loop failed"):
            found.append(Interruption("error", e.t_s, e.message))
    if data.truncated:
        found.append(Interruption("killed", duration_s, "the log ends before its footer: the recording process was "
                                                       "killed (SIGKILL, a crash, power lost); `--salvage` writes a "
                                                       "finished copy"))
    elif clean is False:
        found.append(Interruption("killed", duration_s, "the log has no clean end (the drones' final status is "
                                                       "missing): the recording process was killed; this is a "
                                                       "salvaged or cut copy"))
    return found


# ---------------------------------------------------------------------------------------------- series


def _seconds(msgs: list, start_ns: int) -> np.ndarray:
    return (np.array([m.log_time for m in msgs], dtype=np.int64) - start_ns) / 1e9


def pose_series(data: LogData, drone: str, start_ns: int, topic: str = "") -> Series:
    """``(n, 3)`` positions of ``/mocap/<drone>`` (or ``topic``: a PoseInFrame topic) over time."""
    msgs = data.messages(topic or f"/mocap/{drone}")
    xyz = np.array([[m.data["pose"]["position"][k] for k in "xyz"] for m in msgs], dtype=float).reshape(-1, 3)
    return Series(_seconds(msgs, start_ns), xyz)


def _interp(t: np.ndarray, series: Series) -> np.ndarray:
    """``series`` at times ``t`` (linear; NaN outside its time range)."""
    out = np.full((t.size, series.values.shape[1]), np.nan)
    if series.t.size == 0:
        return out
    inside = (t >= series.t[0]) & (t <= series.t[-1])
    for c in range(series.values.shape[1]):
        out[inside, c] = np.interp(t[inside], series.t, series.values[:, c])
    return out


def tracking_error(data: LogData, drone: str, start_ns: int) -> Series:
    """|setpoint - pose| (3D, metres) at each setpoint's time, the pose interpolated there."""
    setpoints = pose_series(data, drone, start_ns, f"/{drone}/setpoint")
    poses = pose_series(data, drone, start_ns)
    at = _interp(setpoints.t, poses)
    err = np.linalg.norm(setpoints.values - at, axis=1) if setpoints.t.size else np.zeros(0)
    keep = np.isfinite(err)
    return Series(setpoints.t[keep], err[keep])


def tracking_expectation(data: LogData, drone: str, start_ns: int, lag_s: float) -> TrackingExpectation:
    """The drone's tracking error while cruising against ``lag_s`` x the setpoint's speed. At each setpoint whose
    last ``2 lag_s`` of setpoints lie in the log (the lag has built up: 86 % of it for a first-order follower), the
    speed is the setpoints' path over that window divided by it; a setpoint is cruising at
    :data:`CRUISE_MIN_SPEED_M_S` or more. Medians over the cruising setpoints: the flown speed, the expected
    ``lag_s x speed`` and the measured ``|setpoint - pose|``."""
    setpoints = pose_series(data, drone, start_ns, f"/{drone}/setpoint")
    poses = pose_series(data, drone, start_ns)
    none = TrackingExpectation(drone, lag_s, 0)
    if setpoints.t.size < 2:
        return none
    err = np.linalg.norm(setpoints.values - _interp(setpoints.t, poses), axis=1)
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(setpoints.values, axis=0), axis=1))])
    window = 2.0 * lag_s
    full = setpoints.t - window >= setpoints.t[0]
    speed = (path - np.interp(setpoints.t - window, setpoints.t, path)) / window
    cruising = full & (speed >= CRUISE_MIN_SPEED_M_S) & np.isfinite(err)
    count = int(cruising.sum())
    if count < 5:
        return TrackingExpectation(drone, lag_s, count)
    v = float(np.median(speed[cruising]))
    return TrackingExpectation(drone, lag_s, count, speed_m_s=v, expected_m=float(np.median(lag_s * speed[cruising])),
                               measured_m=float(np.median(err[cruising])))


def rms_max(values: np.ndarray) -> tuple[Optional[float], Optional[float]]:
    if values.size == 0:
        return None, None
    return float(np.sqrt(np.mean(values**2))), float(values.max())


def min_separation(data: LogData, drones: list[str], start_ns: int) -> Series:
    """Smallest planar centre distance of any pair over time, on the first drone's mocap times."""
    if len(drones) < 2:
        return Series(np.zeros(0), np.zeros(0))
    tracks = [pose_series(data, d, start_ns) for d in drones]
    base = next((s.t for s in tracks if s.t.size), np.zeros(0))
    if base.size == 0:
        return Series(base, np.zeros(0))
    xy = np.stack([_interp(base, s)[:, :2] for s in tracks], axis=1)  # (n, N, 2)
    points = xy[..., 0] + 1j * xy[..., 1]
    d = abs(points[:, :, None] - points[:, None, :])
    n = len(drones)
    d[:, np.arange(n), np.arange(n)] = np.inf
    d = np.where(np.isnan(d), np.inf, d)
    low = d.reshape(base.size, -1).min(axis=1)
    keep = np.isfinite(low)
    return Series(base[keep], low[keep])


def obstacle_clearance(data: LogData, drone: str, start_ns: int, scenario: Optional[dict[str, Any]]) -> Series:
    """Planar distance from the drone's centre (``/mocap``) to the nearest obstacle surface over time (metres,
    negative inside; what the metrics' ``min_obstacle_clearance_m`` and a collision, ``< r``, are measured on).
    Empty without obstacles."""
    if not scenario or not scenario.get("obstacles"):
        return Series(np.zeros(0), np.zeros(0))
    poses = pose_series(data, drone, start_ns)
    if poses.t.size == 0:
        return Series(poses.t, np.zeros(0))
    points = poses.values[:, 0] + 1j * poses.values[:, 1]
    return Series(poses.t, np.asarray(obstacle_set_of(scenario).signed_distance(points), dtype=float))


def battery_series(data: LogData, drone: str, start_ns: int) -> Series:
    msgs = [m for m in data.messages(f"/{drone}/status") if m.data.get("battery_v") is not None]
    return Series(_seconds(msgs, start_ns), np.array([m.data["battery_v"] for m in msgs], dtype=float))


def phases(data: LogData, drone: str, start_ns: int, end_s: float) -> list[tuple[float, float, str]]:
    """``(start_s, end_s, state)`` segments of the drone's ``/status`` states."""
    out: list[tuple[float, float, str]] = []
    for m in data.messages(f"/{drone}/status"):
        t = (m.log_time - start_ns) / 1e9
        state = str(m.data.get("state", ""))
        if out and out[-1][2] == state:
            continue
        if out:
            out[-1] = (out[-1][0], t, out[-1][2])
        out.append((t, end_s, state))
    return out


# ---------------------------------------------------------------------------------------------- CSV


def _flatten(value: Any, prefix: str, row: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(v, f"{prefix}.{k}" if prefix else str(k), row)
    elif isinstance(value, list):
        row[prefix] = json.dumps(value, separators=(",", ":"))
    else:
        row[prefix] = "" if value is None else value


def csv_name(topic: str) -> str:
    """File name of a topic's CSV: ``/mocap/cf1`` -> ``mocap_cf1.csv``."""
    return topic.strip("/").replace("/", "_") + ".csv"


def export_csv(data: LogData, directory: str | Path) -> list[Path]:
    """One CSV per topic: ``log_time_ns, publish_time_ns, sequence`` and the message's fields flattened with dots
    (``pose.position.x``); arrays as JSON in one cell; null as an empty cell."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for topic in sorted(data.topics):
        rows = []
        columns: dict[str, None] = {"log_time_ns": None, "publish_time_ns": None, "sequence": None}
        for m in data.messages(topic):
            row: dict[str, Any] = {"log_time_ns": m.log_time, "publish_time_ns": m.publish_time, "sequence": m.sequence}
            if isinstance(m.data, dict):
                _flatten(m.data, "", row)
            else:
                row["data"] = m.data.hex() if isinstance(m.data, (bytes, bytearray)) else m.data
            columns.update(dict.fromkeys(row))
            rows.append(row)
        for name in [c for c in columns if any(d.startswith(c + ".") for d in columns)]:
            if all(row.get(name, "") == "" for row in rows):  # a nullable object, null in some rows: its fields are
                del columns[name]                             # the columns
        path = directory / csv_name(topic)
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(columns), restval="")
            writer.writeheader()
            writer.writerows(rows)
        written.append(path)
    return written
