"""The review's time series, for its judgements and its figure: positions and altitude from ``/mocap``, setpoint
tracking error (each setpoint against the pose interpolated at the setpoint's log time), minimum planar separation
over the mocap times of the first drone (other drones interpolated), obstacle clearance, battery and flight states
from ``/status``.

Times are seconds from the start of the log (the log time minus the file's first log time).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rpf_fly.log.reader import LogData
from rpf_fly.log.review_scenario import obstacle_set_of


@dataclass
class Series:
    """Time series of one drone (seconds from the start of the log)."""

    t: np.ndarray
    values: np.ndarray


def _seconds(msgs: list, start_ns: int) -> np.ndarray:
    return (np.array([m.log_time for m in msgs], dtype=np.int64) - start_ns) / 1e9


def pose_series(data: LogData, drone: str, start_ns: int, topic: str = "") -> Series:
    """``(n, 3)`` positions of ``/mocap/<drone>`` (or ``topic``: a PoseInFrame topic) over time."""
    msgs = data.messages(topic or f"/mocap/{drone}")
    xyz = np.array([[m.data["pose"]["position"][k] for k in "xyz"] for m in msgs], dtype=float).reshape(-1, 3)
    return Series(_seconds(msgs, start_ns), xyz)


def interp(t: np.ndarray, series: Series) -> np.ndarray:
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
    at = interp(setpoints.t, poses)
    err = np.linalg.norm(setpoints.values - at, axis=1) if setpoints.t.size else np.zeros(0)
    keep = np.isfinite(err)
    return Series(setpoints.t[keep], err[keep])


def rms_max(values: np.ndarray) -> tuple[float | None, float | None]:
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
    xy = np.stack([interp(base, s)[:, :2] for s in tracks], axis=1)  # (n, N, 2)
    points = xy[..., 0] + 1j * xy[..., 1]
    d = abs(points[:, :, None] - points[:, None, :])
    n = len(drones)
    d[:, np.arange(n), np.arange(n)] = np.inf
    d = np.where(np.isnan(d), np.inf, d)
    low = d.reshape(base.size, -1).min(axis=1)
    keep = np.isfinite(low)
    return Series(base[keep], low[keep])


def obstacle_clearance(data: LogData, drone: str, start_ns: int, scenario: dict[str, Any] | None) -> Series:
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
