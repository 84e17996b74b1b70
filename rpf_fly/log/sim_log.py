"""A simulated run written as a flight log: same topics, schemas and metadata as a flight (docs/log-format.md).

Time is simulated: planning tick ``k`` happens at ``SIM_START_NS + k * dt`` and both the log time and the publish
time of every message are that tick time, so the file is deterministic. Per tick and drone: the pose on
``/mocap/<drone>`` (flight height, identity orientation), the planner step (``/<drone>/planner``), the setpoint
sent (``position + speed * dt * direction`` at flight height, the position itself once arrived), the status
(``planning`` then ``arrived``; the outcome on the last tick), and one ``/tf``. ``/scene`` once at the start;
``/events`` for the start, each arrival, each collision entry (the metrics' definition), geofence holds, drones
that did not arrive, and the end. The planner steps cover ticks ``0..T``: the last one (no planning happened
there) records the final position with mode ``arrived``, ``stalled`` or ``hold`` (timed out), so the review
rebuilds the ``(T+1, N)`` positions and reproduces ``rpf-fly sim --json`` exactly.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rpf_fly.log.messages import IDENTITY
from rpf_fly.log.metadata import mission_metadata, obstacle_dict, scenario_metadata
from rpf_fly.log.writer import FlightLog
from rpf_fly.sim.collisions import collision_flags, pair_distances
from rpf_fly.sim.rollout import DroneOutcome, Rollout

SIM_START_NS = 1_700_000_000_000_000_000
"""Start time of simulated logs (2023-11-14T22:13:20Z), ns since the Unix epoch."""

_FINAL_MODE = {DroneOutcome.REACHED: "arrived", DroneOutcome.STALLED: "stalled", DroneOutcome.TIMEOUT: "hold"}


def _entries(flags: np.ndarray) -> np.ndarray:
    """Where a flag turns on (false before the first sample)."""
    before = np.concatenate([np.zeros_like(flags[:1]), flags[:-1]], axis=0)
    return flags & ~before


def write_sim_log(
    path: str | Path, mission: Any, scenario: Any, rollout: Rollout, seed: int, start_ns: int = SIM_START_NS
) -> Path:
    """Write ``rollout`` of ``scenario`` (from ``mission`` with ``seed``) to the MCAP file ``path``.

    Raises ``OSError`` when the file cannot be written."""
    path = Path(path)
    dt = float(rollout.params.dt)
    dt_ns = int(round(dt * 1e9))
    speed = float(rollout.params.speed)
    tolerance = float(rollout.params.goal_tolerance)
    height = float(mission.flight.height)
    r = float(mission.planner.safety_radius)
    sensing = float(mission.planner.sensing_range)
    names = list(scenario.names)
    n = len(names)
    positions = rollout.positions
    steps = rollout.steps
    goals = scenario.goals

    if scenario.obstacles.is_empty:
        surface = clearance = np.full(positions.shape, np.nan)
    else:
        surface = scenario.obstacles.signed_distance(positions)
        clearance = np.where(surface <= sensing, surface, np.nan)  # null: no obstacle in sensing range
    goal_distance = abs(positions - goals)
    near = goal_distance < tolerance
    arrival = np.where(near.any(axis=0), near.argmax(axis=0), -1)
    pairs, obstacle_hits = collision_flags(positions, scenario.obstacles, r)
    pair_entries = _entries(pairs)
    obstacle_entries = _entries(obstacle_hits)
    separation = pair_distances(positions)

    heading = np.angle(goals - positions[0])
    headings = np.empty(positions.shape)
    for k in range(steps + 1):
        if k < steps:
            d = rollout.direction[k]
            moving = abs(d) > 0
            heading = np.where(moving, np.angle(d), heading)
        headings[k] = heading

    shapes = [obstacle_dict(s) for s in scenario.shapes]
    arena = {"x": list(scenario.arena_x), "y": list(scenario.arena_y), "z": list(mission.arena.z)}
    ident = IDENTITY

    log = FlightLog(
        path,
        mission_metadata(mission, seed, source="sim"),
        scenario_metadata(mission, scenario),
        clock=None,
        block_when_full=True,
    )
    with log:
        log.scene(start_ns, shapes, {name: complex(g) for name, g in zip(names, goals)}, arena, height)
        log.event(
            start_ns,
            2,
            f"sim start: mission {mission.name}, planner {mission.planner.kind}, seed {seed}, {n} drones, dt {dt:g} s",
            name="sim",
        )
        for k in range(steps + 1):
            t = start_ns + k * dt_ns
            final = k == steps
            xyz = [(float(p.real), float(p.imag), height) for p in positions[k]]
            for i, name in enumerate(names):
                log.pose(name, t, xyz[i], ident)
            for i, name in enumerate(names):
                common = dict(
                    tick=k,
                    position=xyz[i],
                    goal=complex(goals[i]),
                    heading=float(headings[k, i]),
                    obstacle_distance=float(clearance[k, i]),
                    goal_distance=float(goal_distance[k, i]),
                )
                if final:
                    log.planner_step(
                        name, t, mode=_FINAL_MODE[rollout.outcomes[i]], eta=None, lam=None, neighbours=0, **common
                    )
                    setpoint = xyz[i]
                else:
                    mode = int(rollout.modes[k, i])
                    direction = complex(rollout.direction[k, i])
                    log.planner_step(
                        name,
                        t,
                        mode=mode,
                        eta=float(rollout.eta[k, i]),
                        lam=float(rollout.lam[k, i]),
                        f_a=complex(rollout.f_a[k, i]),
                        f_r=complex(rollout.f_r[k, i]),
                        f_in=complex(rollout.f_in[k, i]),
                        direction=direction,
                        neighbours=int(rollout.neighbours[k, i]),
                        **common,
                    )
                    step = speed * dt * direction if mode >= 0 else 0j
                    setpoint = (xyz[i][0] + step.real, xyz[i][1] + step.imag, height)
                log.setpoint(name, t, setpoint, float(headings[k, i]))
                arrived = 0 <= arrival[i] <= k
                log.status(
                    name,
                    t,
                    state="arrived" if arrived else ("planning" if not final else "hover"),
                    outcome=rollout.outcomes[i].value if final else None,
                )
            log.tf(t, {name: (xyz[i], ident) for i, name in enumerate(names)})
            for i in np.flatnonzero(arrival == k).tolist():
                log.event(t, 2, f"{names[i]} reached its goal at {k * dt:.1f} s", name="sim")
            for i, j in zip(*np.nonzero(np.triu(pair_entries[k], 1))):
                log.event(
                    t,
                    4,
                    f"collision {names[i]}-{names[j]}: centre distance {separation[k, i, j]:.3f} m < 2r = {2 * r:g} m",
                    name="sim",
                )
            for i in np.flatnonzero(obstacle_entries[k]).tolist():
                log.event(
                    t,
                    4,
                    f"collision {names[i]} with an obstacle: clearance {surface[k, i]:.3f} m < r = {r:g} m",
                    name="sim",
                )
        t_end = start_ns + steps * dt_ns
        for i, name in enumerate(names):
            clamps = int(rollout.geofence_clamps[i])
            if clamps:
                log.event(t_end, 3, f"{name} held at the arena boundary for {clamps} steps", name="sim")
            if rollout.outcomes[i] is not DroneOutcome.REACHED:
                log.event(t_end, 3, f"{name} did not reach its goal: {rollout.outcomes[i].value}", name="sim")
        reached = sum(o is DroneOutcome.REACHED for o in rollout.outcomes)
        log.event(t_end, 2, f"sim end after {steps * dt:.1f} s: {reached}/{n} reached", name="sim")
    if log.error is not None:
        raise log.error if isinstance(log.error, OSError) else OSError(str(log.error))
    if log.failed:
        raise RuntimeError(f"{path}: {log.failed} messages could not be built")
    return path
