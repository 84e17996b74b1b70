"""The review's metrics: the metrics JSON of docs/metrics.md, computed by
:func:`rpf_fly.sim.metrics.compute_metrics` from the positions the planner saw at every tick (``/<drone>/planner``,
ticks ``0..T``) and the ``scenario`` metadata record, labelled with the ``mission`` record's name, planner kind and
seed.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.log.reader import LogData
from rpf_fly.log.review_scenario import ReviewError, obstacle_set_of, scenario_of
from rpf_fly.sim.metrics import Metrics, compute_metrics


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
