"""The review's judgement of setpoint tracking: a drone's tracking error while cruising against what its kind of
drone gives at the flown speed (its lag behind a moving setpoint x the setpoint's speed).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from rpf_fly.log.reader import LogData
from rpf_fly.log.review_series import interp, pose_series

CRAZYFLIE_LAG_S = 0.55
"""How far a Crazyflie with the firmware's default gains trails a moving position setpoint, in seconds of the
setpoint's speed: 0.5 s from the position gain (``posCtlPid.xKp`` 2 /s; the setpoint carries no velocity to feed
forward), plus the velocity error its velocity loop needs to hold the tilt that balances drag. The Crazyflie dynamics
reference (the firmware's control code against the identified Crazyflie 2.1+ body) trails carrots by 16.4 cm at
0.3 m/s, 27.3 cm at 0.5 m/s and 55.6 cm at 1 m/s, and a circle the same. A planner's setpoint stream moves at the
flight's speed, so its tracking error while cruising is mostly this lag, not a fault."""

DRY_RUN_LAG_S = 0.25
"""A dry run's first-order simulated drone: a follower of its position setpoint with a time constant of 0.25 s
(rpf_fly/emulator/vehicle_figures.py ``TRACK_TAU_S``), which trails a moving setpoint by 0.25 s x speed, less than a
Crazyflie (``dry_run.dynamics: first-order``; docs/flight.md, *The simulated drone*)."""

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
    speed_m_s: float | None = None
    expected_m: float | None = None
    measured_m: float | None = None

    @property
    def band_m(self) -> tuple[float, float] | None:
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
        return {
            "cruise_samples": self.samples,
            "speed_m_s": self.speed_m_s,
            "expected_m": self.expected_m,
            "measured_m": self.measured_m,
            "low_m": band[0] if band else None,
            "high_m": band[1] if band else None,
            "outside": self.outside,
        }


def tracking_lag(source: str, dynamics: str = "") -> tuple[float, str]:
    """The lag (s) with which the log's drones trail a moving setpoint, and what those drones are: for a dry run or
    a lab, the simulated drone (its first-order follower, or with ``dynamics`` ``firmware`` the firmware's cascade,
    which trails as a Crazyflie does); a Crazyflie with the firmware's default gains otherwise."""
    if source in ("dry-run", "lab"):
        if dynamics == "firmware":
            return CRAZYFLIE_LAG_S, "the dry run's simulated Crazyflies (the firmware's default gains)"
        return DRY_RUN_LAG_S, "the dry run's simulated drones"
    return CRAZYFLIE_LAG_S, "Crazyflies with the firmware's default gains"


def logged_dynamics(mission: Mapping[str, Any]) -> str:
    """The model a dry run's or lab's simulated drones flew, from the log's ``mission`` record: its ``dynamics``,
    else the logged mission's ``dry_run.dynamics``, else ``first-order`` (the default of the versions that wrote
    neither)."""
    return str(mission.get("dynamics", "")) or dry_run_dynamics(str(mission.get("yaml", ""))) or "first-order"


def dry_run_dynamics(mission_yaml: str) -> str:
    """``dry_run.dynamics`` of the logged mission text ("" when it names none or does not read)."""
    import yaml

    try:
        doc = yaml.safe_load(mission_yaml or "") or {}
        value = (doc.get("dry_run") or {}).get("dynamics", "")
    except (yaml.YAMLError, AttributeError):
        return ""
    return value if isinstance(value, str) else ""


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
    err = np.linalg.norm(setpoints.values - interp(setpoints.t, poses), axis=1)
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(setpoints.values, axis=0), axis=1))])
    window = 2.0 * lag_s
    full = setpoints.t - window >= setpoints.t[0]
    speed = (path - np.interp(setpoints.t - window, setpoints.t, path)) / window
    cruising = full & (speed >= CRUISE_MIN_SPEED_M_S) & np.isfinite(err)
    count = int(cruising.sum())
    if count < 5:
        return TrackingExpectation(drone, lag_s, count)
    v = float(np.median(speed[cruising]))
    return TrackingExpectation(
        drone,
        lag_s,
        count,
        speed_m_s=v,
        expected_m=float(np.median(lag_s * speed[cruising])),
        measured_m=float(np.median(err[cruising])),
    )
