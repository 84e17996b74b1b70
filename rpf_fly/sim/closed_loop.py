"""The closed loop on the firmware dynamics model: planners fly simulated Crazyflies as the flight flies real ones.

Why: the kinematic world (:mod:`rpf_fly.sim.world`) moves each drone exactly along its planned heading, so a bench
on it cannot see what a real drone adds: it trails a moving setpoint by about 0.55 s x its speed and overshoots
when the setpoint stops (docs/dynamics.md). Here every drone is one column of a
:class:`~rpf_fly.emulator.cf_swarm.CfSwarm` (the firmware's PID cascade on the identified Crazyflie 2.1 body, 1 kHz
ticks, attitude and rate loops at 500 Hz, position and velocity loops at 100 Hz), and the planner's heading becomes
a position setpoint by the flight's own code: each drone is a :class:`~rpf_fly.flight.agent.DroneAgent`, whose
:meth:`~rpf_fly.flight.agent.DroneAgent.accept` moves its carrot (``ref += v dt d``, at most ``max_lead`` ahead of
the measured position, clamped to the geofence with the body inside) and returns the setpoint the flight streams.

One planning tick (every ``dt``, the mission's rate), per scene, as the flight's tick does it:

1. the measured pose of every drone is its simulated truth (position and velocity) at that instant;
2. a planning drone whose goal is within the tolerance arrives and holds its goal from then on (the commander's
   ``arrive``: its setpoint becomes the goal);
3. every drone's view is built (``plan_from``): ``"flight"`` (the default) as the flight builds it
   (flight/swarm_plan.py, flight/agent.py: each drone plans from its own reference and sees each neighbour at the
   measured position plus its measured velocity times its own observed tracking lag), or ``"truth"``: from the
   true positions and velocities as they are;
4. the scene's planner plans every drone in one batched call (as the kinematic rollout calls it); each planning
   drone's direction goes through its agent to a setpoint, streamed at once (no radio or mocap latency) to its
   simulated drone at the flight height, yaw 0.

Between ticks the swarm steps 10 ms at a time and its truth is recorded every 10 ms (100 Hz): collisions, the
smallest separation and clearance and the margin breaches are judged on that record, not only at the ticks
(:func:`firmware_metrics`); arrival, travel, smoothness and makespan on the truth at the ticks, as the kinematic
rollout samples them. A run ends as the kinematic one does (every drone arrived, or the time limit); after the last
arrival the truth is judged :attr:`FirmwareParams.hold_tail_s` longer, while the drones overshoot their goals and
settle (a hold from 0.5 m/s overshoots by about 11 cm).

Drones start hovering settled at their starts (``CfSwarm.hovering``: rotors at hover speed, the vertical velocity
integrator carrying what thrustBase lacks, ``settle_s`` of hover before t = 0, as the model's setpoint scenarios
start). Not modelled: mocap and radio latency, estimator noise, take-off and landing, contact between drones (they
pass through each other; a collision is counted, never acted on, as in the kinematic world).

Several scenes fly in one swarm (:func:`firmware_rollouts`): the drones of different scenes never interact (each
scene's planner sees only its own drones), and a swarm's tick costs about the same for 6 drones or 120, so the
bench flies all seeds of a (planner, scene) at once, or a whole family (rpf_fly/bench/families.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from rpf_fly.mission.model import Arena, Drone, FlightSettings, PlannerSettings
from rpf_fly.planning.view import LocalView, others_index, views_from_states, views_of_drones
from rpf_fly.sim.metrics import Metrics, compute_metrics
from rpf_fly.sim.rollout import STALL_WINDOW_S, DroneOutcome, Rollout, SimParams
from rpf_fly.sim.scenario import Scenario

if TYPE_CHECKING:
    from rpf_fly.planning.factory import AnyPlanner
    from rpf_fly.sim.evaluate import Run

STEP_S = 0.01
"""s: the swarm is stepped (and its truth recorded) this often: 100 Hz, the firmware's position loop rate."""

PlanFrom = Literal["flight", "truth"]

DYNAMICS = ("kinematic", "firmware")
"""What a bench can fly: the kinematic world (rpf_fly.sim.world) or this closed loop."""


@dataclass(frozen=True)
class FirmwareParams:
    """What the closed loop adds to :class:`~rpf_fly.sim.rollout.SimParams`.

    ``height_m``: the flight height (``flight.height``; the default a mission gets); ``arena_z``: the arena's height
    range (setpoints keep the body under its ceiling; None: a mission's default); ``settle_s``: hover before
    t = 0; ``hold_tail_s``: truth judged this long after the last arrival; ``plan_from``: how the views are built
    (module doc)."""

    height_m: float = FlightSettings().height
    arena_z: tuple[float, float] | None = None
    settle_s: float = 10.0
    hold_tail_s: float = 2.0
    plan_from: PlanFrom = "flight"


@dataclass(frozen=True)
class FirmwareRollout(Rollout):
    """A closed-loop run: the :class:`~rpf_fly.sim.rollout.Rollout` fields sampled at the planning ticks
    (``positions`` is the simulated truth at each tick), plus ``truth`` ``(S, N)`` complex, the true positions every
    ``truth_dt`` s from t = 0 to the end of the run and its hold tail, ``setpoints`` ``(T, N)`` complex, the setpoint
    streamed at each tick, and ``velocity`` ``(T+1, N)`` complex, the true planar
    velocity at each tick. ``geofence_clamps`` counts, per drone, the ticks whose true position lay outside the arena
    (where the kinematic world would have clamped it)."""

    truth: np.ndarray
    truth_dt: float
    setpoints: np.ndarray
    velocity: np.ndarray
    firmware: FirmwareParams


class _Scene:
    """One scene's state in a shared swarm: its columns, agents, planner and records."""

    def __init__(
        self,
        scenario: Scenario,
        planner: AnyPlanner,
        params: SimParams,
        firmware: FirmwareParams,
        settings: PlannerSettings,
        first_column: int,
    ):
        from rpf_fly.flight.agent import DroneAgent

        self.scenario = scenario
        self.planner = planner
        self.params = params
        self.sensing_range = settings.sensing_range
        n = scenario.n_drones
        self.columns = np.arange(first_column, first_column + n)
        (x0, x1), (y0, y1) = scenario.arena_x, scenario.arena_y
        z = firmware.arena_z
        arena = Arena((x0, x1), (y0, y1)) if z is None else Arena((x0, x1), (y0, y1), z)
        # The flight's agents (its carrot, geofence and tracking lag); the planning budget is the flight's worry.
        self.agents = [
            DroneAgent(
                Drone(name, "sim://closed-loop", name, (s.real, s.imag), (g.real, g.imag)),
                planner,
                height=firmware.height_m,
                speed=params.speed,
                dt=params.dt,
                arena=arena,
                budget_s=float("inf"),
                body_radius_m=settings.safety_radius,
            )
            for name, s, g in zip(scenario.names, scenario.starts, scenario.goals)
        ]
        self.z = np.array([a.clamp_height(firmware.height_m) for a in self.agents])
        self.arrived = np.zeros(n, dtype=bool)
        self.planning = False
        self.positions: list[np.ndarray] = []
        self.velocities: list[np.ndarray] = []
        self.truth: list[np.ndarray] = []
        self.setpoints: list[np.ndarray] = []
        self.records: dict[str, list[np.ndarray]] = {
            k: [] for k in ("mode", "eta", "lam", "f_a", "f_r", "f_in", "direction", "neighbours")
        }
        self.clamps = np.zeros(n, dtype=int)
        self.tail_until: int | None = None
        """Truth sample index after which this scene's record ends (set when its run ends)."""

    def sample_tick(self, xy: np.ndarray, velocity: np.ndarray) -> None:
        """Record the truth at a planning tick and mark the drones that arrived."""
        p, v = xy[self.columns], velocity[self.columns]
        self.positions.append(p)
        self.velocities.append(v)
        (x0, x1), (y0, y1) = self.scenario.arena_x, self.scenario.arena_y
        self.clamps += (p.real < x0) | (p.real > x1) | (p.imag < y0) | (p.imag > y1)
        self.arrived |= abs(self.scenario.goals - p) < self.params.goal_tolerance

    def view(self, plan_from: PlanFrom) -> LocalView:
        """Every drone's view at this tick (module doc, step 3)."""
        measured, velocity = self.positions[-1], self.velocities[-1]
        goals = self.scenario.goals
        headings = np.array([a.heading for a in self.agents], dtype=complex)
        if plan_from == "truth":
            return views_from_states(measured, velocity, goals, headings, self.sensing_range)
        idx = others_index(measured.shape[0])
        before = self.velocities[-2] if len(self.velocities) > 1 else velocity
        acceleration = (velocity - before) / self.params.dt  # over the last planning period, as a tracker's filter
        others = np.array(
            [
                a.predict(measured[row], velocity[row], acceleration[row], complex(m))
                for a, row, m in zip(self.agents, idx, measured)
            ]
        ).reshape(idx.shape)
        references = np.array([a.reference for a in self.agents], dtype=complex)
        return views_of_drones(
            references, goals, headings, others, velocity[idx], np.ones(idx.shape, dtype=bool), self.sensing_range
        )

    def plan(self, plan_from: PlanFrom) -> np.ndarray:
        """One planning tick: the setpoint (x + iy) of every drone, planned or held."""
        measured = self.positions[-1]
        n = measured.shape[0]
        if not self.planning:
            for agent, m in zip(self.agents, measured):
                agent.begin_planning(complex(m), 0.0)
            self.planning = True
        step = self.planner.step(self.view(plan_from))
        direction = np.broadcast_to(np.asarray(step.direction, dtype=complex), (n,))
        setpoints = np.empty(n, dtype=complex)
        for i, agent in enumerate(self.agents):
            if self.arrived[i]:  # the commander's arrive: it holds its goal (clamped as every setpoint is)
                setpoints[i] = agent.clamp(agent.goal)
            else:
                setpoints[i] = agent.accept(step, complex(direction[i]), complex(measured[i]), 0.0, row=i).setpoint
        active = ~self.arrived
        self.records["mode"].append(np.where(active, np.broadcast_to(step.mode, (n,)), -1).astype(np.int8))
        for key in ("eta", "lam", "f_a", "f_r", "f_in", "direction", "neighbours"):
            self.records[key].append(np.broadcast_to(getattr(step, key), (n,)).copy())
        self.setpoints.append(setpoints)
        return setpoints

    def rollout(self, firmware: FirmwareParams) -> FirmwareRollout:
        """The run's record; outcomes by the kinematic rollout's rule (rpf_fly.sim.rollout) on the tick truth."""
        params, n = self.params, self.scenario.n_drones
        track = np.array(self.positions)
        window = min(int(round(STALL_WINDOW_S / params.dt)), track.shape[0] - 1)
        progress = abs(track[-1] - track[-1 - window])
        stalled = progress < 0.1 * params.speed * window * params.dt
        outcomes = tuple(
            DroneOutcome.REACHED if self.arrived[i] else (DroneOutcome.STALLED if stalled[i] else DroneOutcome.TIMEOUT)
            for i in range(n)
        )
        dtypes = {
            "mode": np.int8,
            "eta": float,
            "lam": float,
            "f_a": complex,
            "f_r": complex,
            "f_in": complex,
            "direction": complex,
            "neighbours": int,
        }
        stacked: dict[str, np.ndarray] = {
            k: (np.array(v, dtype=dtypes[k]) if v else np.zeros((0, n), dtype=dtypes[k]))
            for k, v in self.records.items()
        }
        return FirmwareRollout(
            scenario=self.scenario,
            params=params,
            positions=track,
            modes=stacked["mode"],
            eta=stacked["eta"],
            lam=stacked["lam"],
            outcomes=outcomes,
            geofence_clamps=self.clamps.copy(),
            f_a=stacked["f_a"],
            f_r=stacked["f_r"],
            f_in=stacked["f_in"],
            direction=stacked["direction"],
            neighbours=stacked["neighbours"],
            truth=np.array(self.truth),
            truth_dt=STEP_S,
            setpoints=np.array(self.setpoints) if self.setpoints else np.zeros((0, n), dtype=complex),
            velocity=np.array(self.velocities),
            firmware=firmware,
        )


def firmware_rollouts(
    scenarios: Sequence[Scenario],
    planners: Sequence[AnyPlanner],
    params: SimParams,
    settings: Sequence[PlannerSettings],
    firmware: FirmwareParams = FirmwareParams(),
) -> list[FirmwareRollout]:
    """Fly every scenario with its own planner (one instance per scenario, as :func:`rpf_fly.sim.evaluate.
    run_scenario` builds one per run) and its planner settings (sensing range, body radius) in one shared swarm;
    each run ends on its own (module doc)."""
    from rpf_fly.emulator.cf_swarm import CfSwarm

    if not len(scenarios) == len(planners) == len(settings):
        raise ValueError("one planner and one planner settings per scenario")
    substeps = round(params.dt / STEP_S)
    if substeps < 1 or abs(substeps * STEP_S - params.dt) > 1e-9:
        raise ValueError(f"the planning step must be a whole number of {STEP_S * 1e3:.0f} ms steps, got {params.dt} s")
    tail = round(firmware.hold_tail_s / STEP_S)
    scenes: list[_Scene] = []
    column = 0
    for scenario, planner, chosen in zip(scenarios, planners, settings):
        scenes.append(_Scene(scenario, planner, params, firmware, chosen, column))
        column += scenario.n_drones
    if not scenes:
        return []
    starts = [(s.real, s.imag, z) for scene in scenes for s, z in zip(scene.scenario.starts, scene.z)]
    swarm = CfSwarm.hovering(starts, t_s=0.0, settle_s=firmware.settle_s)
    drones = [swarm.drone(i) for i in range(swarm.n)]
    sample = 0  # truth samples taken since t = 0

    def truth() -> tuple[np.ndarray, np.ndarray]:
        return swarm.pos[0] + 1j * swarm.pos[1], swarm.vel[0] + 1j * swarm.vel[1]

    xy, velocity = truth()
    for scene in scenes:
        scene.truth.append(xy[scene.columns])
        scene.sample_tick(xy, velocity)
    planning = list(scenes)
    tick = 0
    while True:
        for scene in planning:  # a run ends as the kinematic rollout's does; an arrived one keeps its hold tail
            if scene.arrived.all():
                scene.tail_until = sample + tail
            elif tick >= params.max_steps:
                scene.tail_until = sample  # the time limit: no tail (the flight lands them)
        planning = [s for s in planning if s.tail_until is None]
        # no scene left planning: every one has its tail's end
        if not planning and sample >= max(s.tail_until for s in scenes if s.tail_until is not None):
            break
        for scene in planning:
            setpoints = scene.plan(firmware.plan_from)
            for j, sp, z in zip(scene.columns, setpoints, scene.z):
                drones[j].send_position(sp.real, sp.imag, z, 0.0)
        for _ in range(substeps if planning else 1):
            swarm.step(STEP_S)
            sample += 1
            xy, velocity = truth()
            for scene in scenes:
                if scene.tail_until is None or sample <= scene.tail_until:
                    scene.truth.append(xy[scene.columns])
        for scene in planning:
            scene.sample_tick(xy, velocity)
        tick += 1 if planning else 0
    return [scene.rollout(firmware) for scene in scenes]


def firmware_metrics(rollout: FirmwareRollout, settings: PlannerSettings, label: str = "", seed: int = 0) -> Metrics:
    """The metrics of a closed-loop run: arrival, travel, smoothness and makespan from the truth at the planning
    ticks (as the kinematic rollout is scored); collisions, separation, clearance and margin breaches from the
    100 Hz truth (a pass between two ticks counts); success needs both."""
    sc, p = rollout.scenario, rollout.params
    common: dict[str, Any] = dict(
        goal_tolerance=p.goal_tolerance,
        safety_radius=settings.safety_radius,
        obstacles=sc.obstacles,
        names=sc.names,
        mission=label,
        planner=settings.kind,
        seed=seed,
        margin=settings.margin_m,
    )
    ticks = compute_metrics(rollout.positions, sc.goals, p.dt, **common)
    fine = compute_metrics(rollout.truth, sc.goals, rollout.truth_dt, **common)
    collisions = fine.collisions_drone_drone + fine.collisions_drone_obstacle
    per_drone = tuple(replace(row, collided=f.collided) for row, f in zip(ticks.per_drone, fine.per_drone))
    return replace(
        ticks,
        success=bool(ticks.reached == ticks.drones and collisions == 0),
        collisions_drone_drone=fine.collisions_drone_drone,
        collisions_drone_obstacle=fine.collisions_drone_obstacle,
        min_separation_m=fine.min_separation_m,
        min_obstacle_clearance_m=fine.min_obstacle_clearance_m,
        per_drone=per_drone,
        margin_breaches_drone_drone=fine.margin_breaches_drone_drone,
        margin_breaches_drone_obstacle=fine.margin_breaches_drone_obstacle,
    )


def run_firmware(
    scenarios: Sequence[Scenario],
    settings: PlannerSettings | Sequence[PlannerSettings],
    params: SimParams,
    seeds: Sequence[int],
    labels: Sequence[str],
    firmware: FirmwareParams = FirmwareParams(),
    keep: bool = False,
    planners: Sequence[AnyPlanner] | None = None,
) -> list[Run]:
    """:func:`rpf_fly.sim.evaluate.run_scenario` on the firmware model, for many scenarios flown together: each
    with its planner settings (one for all, or one per scenario) and its own planner (``planners``, else made from
    the settings as the kinematic run makes it), each run scored by :func:`firmware_metrics`. Raises what
    :func:`~rpf_fly.planning.factory.make_planner` raises (an unusable policy) before anything flies."""
    from rpf_fly.planning.factory import make_planner
    from rpf_fly.sim.evaluate import Run

    chosen = [settings] * len(scenarios) if isinstance(settings, PlannerSettings) else list(settings)
    if planners is None:
        planners = [
            make_planner(st, sc.obstacles, (sc.arena_x, sc.arena_y), sc.goals) for sc, st in zip(scenarios, chosen)
        ]
    rollouts = firmware_rollouts(scenarios, planners, params, chosen, firmware)
    return [
        Run(label, st.kind, seed, firmware_metrics(r, st, label, seed), r if keep else None)
        for r, st, seed, label in zip(rollouts, chosen, seeds, labels)
    ]
