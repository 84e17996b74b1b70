"""A drone without mocap: how far it may have drifted from where it believes it is, and how long its landing takes,
which the supervisor weighs against the room around it (docs/flight.md, "Blind")."""

from __future__ import annotations

BLIND_DRIFT_M_S2 = 0.45
"""The default of the mission's ``safety.blind_drift_m_s2``: how fast a drone without mocap may drift off where it
believes it is. Its estimator dead-reckons on a biased accelerometer through its attitude estimate, about 0.5 a t^2
after t s blind. The dry run's drones drift from cited figures (rpf_fly/emulator/fake_vehicle.py): the Crazyflie
2.1's BMI088 accelerometer's typical zero-g offset, 20 mg (0.196 m/s^2, BMI088 data sheet), plus a roll/pitch
error of the estimate of 0.01 rad (g sin 0.57 degrees = 0.098 m/s^2, the Kalman estimator's
`stdDevInitialAttitude_rollpitch`): at most 0.294 m/s^2, and with the velocity error a drone has when it goes
blind, at most 0.18 m after 1 s and 0.64 m after 2 s (200 seeds). 0.45 covers that from 0.5 s blind on (1 s:
0.23 m; 2 s: 0.9 m). Not measured on hardware: a lab that has measured its drones sets its own figure in the
mission."""

BODY_RADIUS_M = 0.065
"""A Crazyflie 2.1's rotor-tip radius: two bodies touch at 0.13 m centre to centre, a body touches an obstacle at
0.065 m from its surface (the dry run's contact figures)."""
BLIND_LAND_S_PER_M = 2.0
"""A drone that lands without mocap lands over this many seconds per metre of height (at least `BLIND_LAND_MIN_S`,
at most the mission's ``land_s``): every second of a blind landing is drift. The high-level commander's landing is a
7th-order polynomial whose peak speed is 2.19 x its mean: 2 s/m keeps it at the firmware's 1.1 m/s vertical limit
(0.5 m: 1 s instead of the mission's 2 s)."""
ESTIMATE_FRESH_S = 0.3
"""A blind drone's height is taken from its on-board estimate when that telemetry is at most this old (three
status samples at 10 Hz)."""
BLIND_LAND_MIN_S = 0.6
LAND_EARLY_SHARE = 0.8
"""A blind drone lands before ``pose_lost_land_s`` when a landing begun any later would end with its possible drift
over this share of the room it has (docs/flight.md, "Blind")."""


def blind_drift_m(blind_s: float, rate_m_s2: float = BLIND_DRIFT_M_S2) -> float:
    """How far a drone blind for ``blind_s`` may have drifted at ``rate_m_s2`` (the mission's
    ``safety.blind_drift_m_s2``)."""
    return 0.5 * rate_m_s2 * blind_s * blind_s


def blind_land_s(height_m: float, land_s: float) -> float:
    """How long a drone at ``height_m`` without mocap takes to land (`BLIND_LAND_S_PER_M`)."""
    return min(land_s, max(BLIND_LAND_MIN_S, BLIND_LAND_S_PER_M * height_m))
