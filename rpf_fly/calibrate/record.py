"""What a calibration fits: one drone's streamed setpoints and where it was, read from a flight log or a trace.

Why a record of its own: a flight log (MCAP, docs/log-format.md) and a trace (the Crazyflie dynamics reference's
JSON, tests/data/crazyflie_dynamics/README.md) say the same two things in different shapes: which position setpoint
was in effect when, and where the drone was. The fit (`rpf_fly.calibrate.fit`) replays the first on the firmware
model and compares the second, so both are brought to one form here: times in seconds from the first setpoint of
the fitted window, the setpoint stream as it was sent (time, x, y, z, yaw), the measured positions, and how the
drone stood at the window's start (hovering, or on the floor with its motors off).

From a log: the drone's ``/<drone>/setpoint`` messages (the window is the longest run of them without a gap over
`MAX_GAP_S`: the streamed part of a flight, between the high-level take-off and landing), its ``/mocap/<drone>``
poses (what a lab has) and, in a dry run, its ``/truth/<drone>`` (to measure the mocap's latency and noise).
From a trace: ``t``, ``sp``, ``pos`` and ``stream_hz`` (inferred from ``sp`` where absent); the setpoint sent at
each stream tick is the ``sp`` of the first sample after it; a stream faster than the samples (100 Hz under
50 Hz samples) or a high-level plan (no ``stream_hz`` and a ``sp`` that moves at every sample) is interpolated
between samples at 100 Hz, the high-level commander's rate.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

MCAP_MAGIC = b"\x89MCAP"
MAX_GAP_S = 0.3
"""A setpoint stream with a longer gap is two streams (the firmware's 0.5 s setpoint watchdog would level the drone
out before the next setpoint: not what the model replays)."""
MIN_WINDOW_S = 2.0
"""The shortest stream worth fitting: a carrot's or a step's transient lasts about 1.5 s."""
FLOOR_Z_M = 0.05
"""A drone lower than this at the window's start stands on the floor (motors off), else it hovers."""
PLAN_RATE_HZ = 100.0
PLAN_PHASE_S = 0.009
"""The high-level commander's setpoint rate and phase: it evaluates its plan at 100 Hz in the stabilizer's own ticks
(`crtp_commander_high_level.c`), 9, 19, 29 ... ms after the loop's first tick (the tick counter starts at 1,
`stabilizer.c:306`; docs/dynamics.md), and the position loop uses that position in the same tick: a plan's positions
are sent then."""


class RecordError(ValueError):
    """The file holds nothing to fit; the message is one line naming the file and what is missing."""


@dataclass(frozen=True)
class FlightRecord:
    """One drone's streamed setpoints and measured positions over the fitted window (times in seconds from the
    window's first setpoint)."""

    path: Path
    drone: str
    kind: str
    """``log`` (an MCAP flight log) or ``trace`` (a trace JSON)."""
    origin: str
    """Where the data came from: a log's ``mission.source`` (``flight``, ``dry-run``, ``scenario``...), a trace's
    ``source`` (``reference``...)."""
    setpoints: np.ndarray
    """(n, 5): t, x, y, z (m), yaw (deg), as sent."""
    positions: np.ndarray
    """(m, 4): t, x, y, z: the mocap's poses (a log) or the trace's ``pos`` (a trace), within the window."""
    truth: np.ndarray | None
    """(k, 4): t, x, y, z of the simulated world's truth (a dry run's log), or None."""
    mocap_frames: np.ndarray | None
    """(j, 4): every logged mocap pose of the drone (t, x, y, z), the window's and the others (for the noise)."""
    end_s: float
    """The window's end: the last setpoint's time plus one stream period."""
    on_floor: bool
    """At the window's start the drone stood on the floor, motors off (else it hovered there)."""
    epoch_ns: int
    """The window's t = 0 on the log's clock (0 for a trace)."""
    warnings: tuple[str, ...] = ()
    """What the file says against its own figures: a dry run whose host could not keep up (its ``/events``)."""

    @property
    def start_position(self) -> tuple[float, float, float]:
        """Where the drone was at t = 0 (the first measured position at or after it)."""
        row = self.positions[0]
        return float(row[1]), float(row[2]), float(row[3])


def read_records(path: Path, drone: str | None = None) -> list[FlightRecord]:
    """Every drone's record in ``path`` (an MCAP log or a trace JSON), or drone ``drone``'s; `RecordError` (one line)
    when the file cannot be read or holds no setpoint stream to fit."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except OSError as err:
        raise RecordError(f"{path}: {err.strerror or err}") from None
    if head == MCAP_MAGIC:
        return _log_records(path, drone)
    return [_trace_record(path, drone)]


# ------------------------------------------------------------------------------------------------- logs


def _quat_yaw_deg(q: dict[str, float]) -> float:
    """The yaw (deg, counter-clockwise from +x) of a logged orientation: a setpoint's yaw is logged so."""
    x, y, z, w = (float(q.get(k, 0.0)) for k in ("x", "y", "z", "w"))
    return math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def _poses(messages: list[Any]) -> np.ndarray:
    """(n, 4): t (s on the log's clock, the frame's time), x, y, z of ``foxglove.PoseInFrame`` messages."""
    rows = []
    for m in messages:
        p = m.data["pose"]["position"]
        rows.append((m.publish_time * 1e-9, p["x"], p["y"], p["z"]))
    return np.array(rows, dtype=float).reshape(-1, 4)


def _longest_stream(times: np.ndarray) -> tuple[int, int]:
    """The index range [i, j) of the longest run of setpoints without a gap over `MAX_GAP_S`."""
    breaks = np.flatnonzero(np.diff(times) > MAX_GAP_S) + 1
    edges = np.concatenate(([0], breaks, [len(times)]))
    spans = [(times[b - 1] - times[a], a, b) for a, b in zip(edges[:-1], edges[1:])]
    _, a, b = max(spans)
    return int(a), int(b)


def _log_records(path: Path, drone: str | None) -> list[FlightRecord]:
    from rpf_fly.log.reader import LogError, read_log

    try:
        data = read_log(path)
    except LogError as err:
        raise RecordError(f"{path}: {err}") from None
    names = sorted(
        topic.split("/")[1]
        for topic in data.topics
        if topic.endswith("/setpoint") and topic.count("/") == 2 and data.topics[topic]
    )
    if not names:
        raise RecordError(
            f"{path}: no setpoints in the log (no /<drone>/setpoint topic): calibrate needs a streamed "
            "flight's log (rpf-fly fly or rpf-fly scenario with --log)"
        )
    if drone is not None:
        if drone not in names:
            raise RecordError(
                f"{path}: --drone {drone}: no setpoints of {drone} in the log (drones with setpoints: "
                f"{', '.join(names)})"
            )
        names = [drone]
    mission = data.metadata.get("mission", {})
    origin = mission.get("source", "") or "flight"
    warnings = tuple(
        str(m.data.get("message", ""))
        for m in data.topics.get("/events", [])
        if "could not keep up" in str(m.data.get("message", ""))
    )  # rpf_fly/emulator/host_lag.py
    if origin in ("dry-run", "lab"):
        from rpf_fly.log.review_tracking import logged_dynamics

        dynamics = logged_dynamics(mission)
        if dynamics != "firmware":
            warnings += (
                f"its simulated drones flew the {dynamics} model (the log's mission record), "
                "not the firmware's cascade: no gains describe them",
            )
    return [_log_record(path, data, name, origin, warnings) for name in names]


def _log_record(path: Path, data: Any, name: str, origin: str, warnings: tuple[str, ...]) -> FlightRecord:
    messages = data.topics[f"/{name}/setpoint"]
    stamps = np.array([m.publish_time for m in messages], dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    messages = [messages[i] for i in order]
    stamps = stamps[order]
    seconds = stamps * 1e-9
    a, b = _longest_stream(seconds)
    if b - a < 2 or seconds[b - 1] - seconds[a] < MIN_WINDOW_S:
        raise RecordError(
            f"{path}: {name}: its longest setpoint stream lasts {seconds[b - 1] - seconds[a]:.2f} s "
            f"(at least {MIN_WINDOW_S:g} s without a gap over {MAX_GAP_S:g} s needed)"
        )
    epoch_ns = int(stamps[a])
    t0 = epoch_ns * 1e-9
    rows = []
    for m in messages[a:b]:
        p = m.data["pose"]["position"]
        rows.append((m.publish_time * 1e-9 - t0, p["x"], p["y"], p["z"], _quat_yaw_deg(m.data["pose"]["orientation"])))
    setpoints = np.array(rows, dtype=float)
    period = float(np.median(np.diff(setpoints[:, 0]))) if len(setpoints) > 1 else 0.1
    end_s = float(setpoints[-1, 0] + min(period, 0.1))
    mocap = data.topics.get(f"/mocap/{name}", [])
    if not mocap:
        raise RecordError(f"{path}: {name}: no mocap poses (/mocap/{name}) in the log: nothing says where it flew")
    frames = _poses(mocap)
    frames[:, 0] -= t0
    inside = (frames[:, 0] >= 0.0) & (frames[:, 0] <= end_s)
    if inside.sum() < 10:
        raise RecordError(
            f"{path}: {name}: {int(inside.sum())} mocap poses during its setpoint stream (at least 10 needed)"
        )
    truth = None
    truth_messages = data.topics.get(f"/truth/{name}", [])
    if truth_messages:
        truth = np.array(
            [
                (m.publish_time * 1e-9 - t0, m.data["position"]["x"], m.data["position"]["y"], m.data["position"]["z"])
                for m in truth_messages
            ],
            dtype=float,
        )
        truth = truth[np.argsort(truth[:, 0], kind="stable")]
    first = frames[inside][0]
    return FlightRecord(
        path=path,
        drone=name,
        kind="log",
        origin=origin,
        setpoints=setpoints,
        positions=frames[inside],
        truth=truth,
        mocap_frames=frames,
        end_s=end_s,
        on_floor=bool(first[3] < FLOOR_Z_M),
        epoch_ns=epoch_ns,
        warnings=warnings,
    )


# ----------------------------------------------------------------------------------------------- traces


def _trace_record(path: Path, drone: str | None) -> FlightRecord:
    expected = "a trace JSON with t, sp and pos (tests/data/crazyflie_dynamics/README.md)"
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise RecordError(f"{path}: neither an MCAP flight log nor {expected}") from None
    if not isinstance(doc, dict) or not all(isinstance(doc.get(k), list) for k in ("t", "sp", "pos")):
        raise RecordError(f"{path}: not {expected}: missing t, sp or pos")
    try:
        t = np.array(doc["t"], dtype=float)
        sp = np.array(doc["sp"], dtype=float).reshape(len(t), 3)
        pos = np.array(doc["pos"], dtype=float).reshape(len(t), 3)
    except (TypeError, ValueError):
        raise RecordError(f"{path}: not {expected}: t must be numbers, sp and pos [x, y, z] per sample") from None
    if len(t) < 10 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(sp)) and np.all(np.isfinite(pos))):
        raise RecordError(f"{path}: a trace needs at least 10 finite samples, has {len(t)}")
    if t[-1] - t[0] < MIN_WINDOW_S:
        raise RecordError(f"{path}: the trace lasts {t[-1] - t[0]:.2f} s (at least {MIN_WINDOW_S:g} s needed)")
    name = drone or str(doc.get("name") or Path(path).stem)
    hz = doc.get("stream_hz")
    on_floor = bool(pos[0, 2] < FLOOR_Z_M)
    stream_hz = float(hz) if isinstance(hz, (int, float)) and hz > 0 else _stream_rate(t, sp, on_floor)
    setpoints = _trace_stream(t, sp, stream_hz)
    dt = float(np.median(np.diff(t)))
    end_s = float(t[-1] + dt)
    return FlightRecord(
        path=path,
        drone=name,
        kind="trace",
        origin=str(doc.get("source") or "trace"),
        setpoints=setpoints,
        positions=np.column_stack([t, pos]),
        truth=None,
        mocap_frames=None,
        end_s=end_s,
        on_floor=on_floor,
        epoch_ns=0,
    )


def _stream_rate(t: np.ndarray, sp: np.ndarray, on_floor: bool) -> float | None:
    """A trace's stream rate where it does not say: None for a high-level plan (a trace that starts on the floor:
    the reference's command scenarios take off with the high-level commander, its setpoint scenarios start from a
    hover); else from where ``sp`` changes, 100 Hz (the position loop's rate) where it changes at every sample."""
    if on_floor:
        return None
    changed = np.flatnonzero(np.any(np.abs(np.diff(sp, axis=0)) > 1e-9, axis=1)) + 1
    if len(changed) < 2:
        return 10.0  # a step: one change, any rate gives the same stream
    gap = float(np.median(np.diff(t[changed])))
    return PLAN_RATE_HZ if gap < 1.5 * float(np.median(np.diff(t))) else 1.0 / gap


def _trace_stream(t: np.ndarray, sp: np.ndarray, stream_hz: float | None) -> np.ndarray:
    """The setpoints as sent: at each stream tick the ``sp`` of the samples it was in effect for (interpolated
    between samples where the stream is faster than them, or for a plan)."""
    sample_hz = 1.0 / float(np.median(np.diff(t)))
    phase = 0.0
    if stream_hz is None:  # a plan: positions at the commander's ticks, between the samples' instants
        sent, values = t, sp
        rate, phase = PLAN_RATE_HZ, PLAN_PHASE_S
    else:
        sent = np.floor(t * stream_hz + 1e-6) / stream_hz
        keep = np.concatenate(([True], np.diff(sent) > 1e-9))
        sent, values = sent[keep], sp[keep]
        rate = stream_hz
        if stream_hz <= sample_hz + 1e-9:  # every tick has a sample: the values as they are, no interpolation
            return np.column_stack([sent, values, np.zeros(len(sent))])
    ticks = np.arange(0, int(math.floor(t[-1] * rate + 1e-6)) + 1) / rate + phase
    cols = [np.interp(ticks, sent, values[:, i]) for i in range(3)]
    return np.column_stack([ticks, *cols, np.zeros(len(ticks))])
