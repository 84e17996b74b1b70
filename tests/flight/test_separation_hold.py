"""A separation hold at 1 m/s keeps two drones apart on the firmware model (docs/flight.md, "Separation and
clearance"): the supervisor holds a closing pair while braking from where they are still keeps them 2r apart
(rpf_fly/flight/response.py), the hold setpoint goes out at once and brings each drone to rest where it braked to,
and a held pair resumes only at rest and clear.

Two drones fly head-on at 1 m/s on planners that cannot see each other (sensing range 5 cm): only the supervisor
stands between them: 2r apart through the first hold at 1 m/s, and never in contact through every hold after a
resume. Judged on the simulated truth."""

from __future__ import annotations

import math
from pathlib import Path

from flight_harness import fly_on_time

from rpf_fly.mission import parse_mission

HEAD_ON = """\
name: head-on-1ms
arena: {x: [-3.0, 3.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 1.0, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 10}
planner: {kind: apf, margin: 0, sensing_range: 0.05}
mocap: {kind: sim, rate_hz: 100}
safety: {on_separation: hold}
dry_run: {dynamics: firmware}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-2.0, 0.0], goal: [2.0, 0.0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [2.0, 0.0], goal: [-2.0, 0.0]}
"""


CONTACT_M = 0.13
"""Two simulated Crazyflies closer than this (centre to centre, a Crazyflie 2.1's rotor-tip span) are in contact."""


def _xyz(sample: dict) -> tuple[float, float, float]:
    p = sample["position"]
    return (p["x"], p["y"], p["z"]) if isinstance(p, dict) else tuple(p)  # type: ignore[return-value]


def test_a_separation_hold_at_1_m_s_keeps_the_drones_apart(tmp_path: Path) -> None:
    mission = parse_mission(HEAD_ON, "head-on.yaml")
    flight = fly_on_time(mission, tmp_path)
    assert not [s for s in flight.snapshots.values() if s.crashed], flight.snapshots
    truth = {
        name: [(m.log_time / 1e9, _xyz(m.data)) for m in flight.log.messages(f"/truth/{name}")]
        for name in ("cf1", "cf2")
    }
    pairs = list(zip(truth["cf1"], truth["cf2"]))
    held = [
        e
        for e in flight.log.messages("/events")
        if e.data.get("file") == "separation" and "closing" in str(e.data.get("message"))
    ]  # the log's event: kind in "file", drone in "name"
    assert held, "the supervisor never held the closing pair"
    first = held[0].log_time / 1e9
    # flying at the mission's 1 m/s when it held them (the carrot leads far enough on the firmware's lag)
    before = [(t, p) for t, p in truth["cf1"] if first - 0.3 <= t <= first]
    speed = math.dist(before[-1][1][:2], before[0][1][:2]) / (before[-1][0] - before[0][0])
    assert speed >= 0.9, speed
    # braking from 1 m/s each (2 m/s closing) they stay 2r apart (2r = 0.2 m) until the hold ends
    resumed = [
        e.log_time / 1e9
        for e in flight.log.messages("/events")
        if e.data.get("file") == "separation" and "restored" in str(e.data.get("message")) and e.log_time / 1e9 > first
    ]
    end = resumed[0] if resumed else first + 3.0
    episode = [
        (round(t - first, 2), round(math.dist(a[:2], b[:2]), 3)) for (t, a), (_, b) in pairs if first <= t <= end
    ]
    assert min(d for _, d in episode) >= 2 * mission.planner.safety_radius, episode[::5]
    # and after each resume (the planners fly at each other again, speeding up from rest) they are held again
    # before they touch: the check predicts each drone's stop from where its speeding up has taken it by the time
    # the hold reaches it, and from the next carrot its planner may send (on an idle host they stay 2r apart,
    # 0.235-0.268 m in six runs; a loaded 2-core CI host's late hold let a pair come to 0.164 m: docs/flight.md)
    resumes = [e for e in flight.log.messages("/events") if "restored" in str(e.data.get("message"))]
    assert resumes, "the held pair never resumed"
    airborne = [(round(t - first, 2), math.dist(a, b)) for (t, a), (_, b) in pairs if a[2] > 0.1 and b[2] > 0.1]
    closest = min(airborne, key=lambda x: x[1])
    assert closest[1] > CONTACT_M, closest
