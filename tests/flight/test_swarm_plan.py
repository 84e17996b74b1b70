"""SwarmPlanner: one batched call gives every drone what its own call would; faults stay the faulty drone's."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rpf_fly.flight.agent import DroneAgent, PlannerFault, PlanResult
from rpf_fly.flight.commander import UNCOMMANDED_DOWN_S
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner, in_the_way, same_function
from rpf_fly.mission.model import Arena, Drone
from rpf_fly.planning import FixedGains, ObstacleSet, Planner, PlannerConfig
from rpf_fly.planning.onnx_policy import OnnxGains, OnnxPolicy

ROOT = Path(__file__).resolve().parents[2]
OBSTACLES = ObstacleSet.from_shapes(circles=[((0.0, 0.4), 0.3)], boxes=[((1.5, -2.0), (2.0, -1.2))])
ARENA = Arena(x=(-4.0, 4.0), y=(-4.0, 4.0), z=(0.0, 2.0))


def swarm(make_planner, n: int = 6, seed: int = 0):  # type: ignore[no-untyped-def]
    """``n`` agents mid-flight around the obstacles (some hovering: static neighbours), with their measured poses."""
    rng = np.random.default_rng(seed)
    angles = 2 * np.pi * np.arange(n) / n
    start = 2.2 * np.exp(1j * angles)
    agents = []
    for i in range(n):
        drone = Drone(
            name=f"cf{i}",
            uri=f"radio://0/80/2M/E7E7E7E70{i}",
            rigid_body=f"cf{i}",
            start=(start[i].real, start[i].imag),
            goal=(-start[i].real, -start[i].imag),
        )
        agent = DroneAgent(drone, make_planner(), height=1.0, speed=0.5, dt=0.01, arena=ARENA, budget_s=1.0)
        agent.begin_planning(start[i] * rng.uniform(0.3, 0.9), 0.0)
        agent.heading = np.exp(1j * rng.uniform(-np.pi, np.pi))
        agents.append(agent)
    measured = np.array([a.reference for a in agents]) - 0.05 * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    velocity = 0.5 * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    velocity[::3] = 0.02  # hovering: the robust preset treats them as obstacles
    acceleration = 2.0 * np.exp(1j * rng.uniform(-np.pi, np.pi, n))  # speeding up or braking: predicted further
    world = Neighbourhood([a.name for a in agents], measured, velocity, acceleration)
    return agents, [(a, complex(m)) for a, m in zip(agents, measured)], world


def fixed() -> Planner:
    return Planner(OBSTACLES, PlannerConfig.robust(), FixedGains())


def learned() -> Planner:
    return Planner(OBSTACLES, PlannerConfig.robust(), OnnxGains(OnnxPolicy(ROOT / "policies" / "rpf.onnx")))


GUIDED = PlannerConfig.robust(guidance="path", margin=0.05)


def guided_fixed() -> Planner:
    """The product's defaults: guidance path and margin 0.05 (drones cross the circle through the obstacles)."""
    return Planner(OBSTACLES, GUIDED, FixedGains(), ((-4.0, 4.0), (-4.0, 4.0)))


def guided_learned() -> Planner:
    return Planner(OBSTACLES, GUIDED, OnnxGains(OnnxPolicy(ROOT / "policies" / "rpf.onnx")), ((-4.0, 4.0), (-4.0, 4.0)))


def plan_twice(make_planner, **kw):  # type: ignore[no-untyped-def]
    """The same tick planned batched and alone, from identical agent states."""
    results = []
    for batching in (True, False):
        agents, requests, world = swarm(make_planner, **kw)
        results.append(SwarmPlanner(6.0, 1.0, batching=batching).plan(requests, world))
    return results


@pytest.mark.parametrize(
    "make_planner, atol", [(fixed, 1e-12), (learned, 1e-5), (guided_fixed, 1e-12), (guided_learned, 1e-5)]
)
def test_batched_call_gives_each_drone_what_its_own_call_gives(make_planner, atol):
    batched, alone = plan_twice(make_planner)
    assert batched.keys() == alone.keys() and len(batched) == 6
    for name, result in batched.items():
        assert isinstance(result, PlanResult) and result.row is not None  # it really was batched
        own = alone[name]
        assert own.row is None
        assert result.setpoint == pytest.approx(own.setpoint, abs=atol)
        step, own_step = result.step, own.step
        for field in ("direction", "f_a", "f_r", "f_in", "eta", "lam", "obstacle_distance", "goal_distance"):
            assert complex(getattr(step, field)) == pytest.approx(complex(getattr(own_step, field)), abs=atol), field
        assert int(step.mode) == int(own_step.mode) and int(step.neighbours) == int(own_step.neighbours)
        if own_step.waypoint is not None:
            assert complex(step.waypoint) == pytest.approx(complex(own_step.waypoint), abs=1e-12)
    if make_planner in (guided_fixed, guided_learned):  # some drone's goal is behind an obstacle
        goals = {a.name: complex(a.goal) for a in swarm(make_planner)[0]}
        assert any(complex(r.step.waypoint) != goals[name] for name, r in batched.items())
    modes = {int(r.step.mode) for r in batched.values()}
    counts = {int(r.step.neighbours) for r in batched.values()}
    assert len(counts) > 1 or len(modes) > 1  # the scene exercises more than one code path


def test_learned_batch_rows_carry_their_own_observation():
    batched, alone = plan_twice(learned)
    for name, result in batched.items():
        mine, own = result.step.observation, alone[name].step.observation
        np.testing.assert_array_equal(mine.mask, own.mask)
        np.testing.assert_allclose(mine.local, own.local, atol=1e-6)
        np.testing.assert_allclose(mine.neighbours, own.neighbours, atol=1e-6)


class NanForOneRow(FixedGains):
    """A shared gains source that poisons one drone's row (by its goal distance) and nothing else."""

    needs_observation: bool = True
    max_neighbours: int = 10

    def __init__(self, poisoned_goal_distance: float):
        object.__setattr__(self, "poisoned", poisoned_goal_distance)

    def gains(self, observation):  # type: ignore[no-untyped-def]
        d_g = observation.local[..., 2]
        eta = np.where(np.isclose(d_g, self.poisoned, atol=1e-4), np.nan, 0.05)
        return eta, 2.0


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_a_non_finite_row_is_planned_alone_and_is_that_drones_fault_only():
    agents, requests, world = swarm(fixed)
    victim = agents[2]
    gains = NanForOneRow(abs(victim.goal - victim.reference))
    shared = Planner(OBSTACLES, PlannerConfig.robust(), gains)
    for agent in agents:
        agent.planner = shared
    planner = SwarmPlanner(6.0, 1.0)
    out = planner.plan(requests, world)
    assert isinstance(out[victim.name], PlannerFault) and "invalid direction" in str(out[victim.name])
    assert all(isinstance(out[a.name], PlanResult) and out[a.name].row is not None for a in agents if a is not victim)
    assert planner.batching


def test_a_raising_batch_falls_back_to_each_drones_own_planner():
    agents, requests, world = swarm(fixed)

    class RaisesOnBatches(Planner):
        def step(self, view):  # type: ignore[no-untyped-def]
            if np.ndim(view.position):
                raise FloatingPointError("batch failure")
            return super().step(view)

    shared = RaisesOnBatches(OBSTACLES, PlannerConfig.robust(), FixedGains())
    for agent in agents:
        agent.planner = shared
    assert not same_function(shared, shared)  # a subclass is never batched: it may not be row-wise
    out = SwarmPlanner(6.0, 1.0).plan(requests, world)
    assert all(isinstance(r, PlanResult) and r.row is None for r in out.values())


def test_a_slow_batch_turns_batching_off_with_a_note():
    agents, requests, world = swarm(fixed)
    ticks = iter([0.0, 0.5])
    planner = SwarmPlanner(6.0, 0.05, clock=lambda: next(ticks))
    out = planner.plan(requests, world)
    assert all(isinstance(r, PlanResult) for r in out.values())  # the results of that tick are valid and used
    assert not planner.batching and "planning each drone alone from now on" in planner.notes[0]


def test_planners_of_different_functions_are_not_batched_together():
    a, b = fixed(), Planner(OBSTACLES, PlannerConfig.robust(), FixedGains(eta=0.07))
    c = Planner(ObstacleSet.empty(), PlannerConfig.robust(), FixedGains())
    d = Planner(OBSTACLES, PlannerConfig.paper(), FixedGains())
    assert same_function(a, fixed()) and same_function(learned(), learned())
    assert not any(same_function(a, other) for other in (b, c, d, learned()))


class Blocking:
    """A user's planner (not the product's: planned on its own thread) that blocks until released on its
    ``block_on``-th call."""

    def __init__(self, planner: Planner, block_on: int = 0):
        import threading

        self.planner, self.block_on, self.calls = planner, block_on, 0
        self.release = threading.Event()

    def step(self, view):  # type: ignore[no-untyped-def]
        self.calls += 1
        if self.calls == self.block_on:
            self.release.wait(10.0)
        return self.planner.step(view)


def test_an_isolated_planner_that_blocks_holds_back_no_other_drone_and_is_faulted_after_the_deadline():
    """Three drones with a user's planner (each on its own thread); one blocks. The tick hands out every view at
    once: the two that answer come back within the wait, the blocked one has no answer (its drone stays on its
    reference), and a later tick faults it once its call is older than the deadline."""
    import time

    agents, requests, world = swarm(fixed, n=3)
    for agent in agents:
        agent.planner = Blocking(fixed(), block_on=1 if agent is agents[1] else 0)
    swarm_planner = SwarmPlanner(6.0, 1.0, hang_s=0.3)
    started = time.monotonic()
    tick = swarm_planner.start(requests, world)
    assert tick.ready == {}  # every drone is isolated: all were handed their views
    answered = dict(tick.collect(0.1))
    assert time.monotonic() - started < 0.25  # never the blocked call's deadline
    assert set(answered) == {agents[0].name, agents[2].name}
    assert all(isinstance(r, PlanResult) for r in answered.values())
    # The next tick, before the deadline: the two answer again, the blocked one still has nothing.
    tick = swarm_planner.start(requests, world)
    assert agents[1].name not in tick.ready
    assert set(dict(tick.collect(0.1))) == {agents[0].name, agents[2].name}
    time.sleep(0.3)
    tick = swarm_planner.start(requests, world)
    fault = tick.ready[agents[1].name]
    assert isinstance(fault, PlannerFault) and "did not return within 300 ms" in str(fault)
    dict(tick.collect(0.1))
    # Released later, its worker answers a call nobody waits for; a new call is refused while it was busy, and
    # taken again once it is free.
    agents[1].planner.release.set()
    time.sleep(0.05)
    assert isinstance(swarm_planner.plan(requests, world)[agents[1].name], PlanResult)


def test_an_answer_that_comes_after_its_tick_is_taken_at_the_next():
    """A planner slower than the tick's wait (but within the deadline) is not faulted: its answer is taken at
    the next tick, and the drone moves on from it."""
    import threading
    import time

    agents, requests, world = swarm(fixed, n=2)
    gate = threading.Event()

    class Slow:
        def __init__(self) -> None:
            self.planner = fixed()

        def step(self, view):  # type: ignore[no-untyped-def]
            gate.wait(5.0)
            return self.planner.step(view)

    agents[0].planner = Slow()
    swarm_planner = SwarmPlanner(6.0, 1.0, hang_s=1.0)
    tick = swarm_planner.start(requests, world)
    assert set(tick.ready) == {agents[1].name}  # the product's planner, inline
    assert dict(tick.collect(0.02)) == {}
    before = agents[0].reference
    gate.set()
    time.sleep(0.05)
    tick = swarm_planner.start(requests, world)
    late = tick.ready[agents[0].name]
    assert isinstance(late, PlanResult) and late.setpoint != before


def test_hung_planners_are_waited_for_together_not_one_after_the_other():
    """The synchronous ``plan`` (replay, tools) waits for every isolated call at once: two blocked planners cost one
    deadline, not two."""
    import time

    agents, requests, world = swarm(fixed, n=3)
    blocked = [Blocking(fixed(), block_on=1), Blocking(fixed(), block_on=1)]
    agents[0].planner, agents[1].planner = blocked
    agents[2].planner = Blocking(fixed())
    started = time.monotonic()
    out = SwarmPlanner(6.0, 1.0, hang_s=0.3).plan(requests, world)
    took = time.monotonic() - started
    for planner in blocked:
        planner.release.set()
    assert all(isinstance(out[a.name], PlannerFault) for a in agents[:2])
    assert isinstance(out[agents[2].name], PlanResult)
    assert took < 0.5, took  # one after the other: 0.6 s


def test_a_drone_nobody_commands_leaves_the_views_once_the_firmware_has_surely_stopped_it():
    """Link lost or motors cut: in the others' way while mocap sees it off the floor, and while its frozen pose is
    younger than the firmware's watchdog and a fall; a frozen pose older than that (a crashed drone whose track
    mocap refused as a jump) is nobody's neighbour any more. A seen drone above the floor stays, however long."""
    for phase in (DronePhase.LINK_LOST, DronePhase.EMERGENCY):
        assert in_the_way(phase, 0.5, 0.5)
        assert in_the_way(phase, 0.5, 0.5, unseen_s=UNCOMMANDED_DOWN_S - 0.01)
        assert not in_the_way(phase, 0.5, 0.5, unseen_s=UNCOMMANDED_DOWN_S + 0.01)
        assert not in_the_way(phase, 0.05, 0.5)  # on the floor
    assert UNCOMMANDED_DOWN_S >= 2.0 + math.sqrt(2 * 1.5 / 9.81)  # the watchdog's 2 s and a fall from 1.5 m
    # the drones the flight commands are judged by height, however old their pose (the stale-pose hold covers them)
    assert in_the_way(DronePhase.HOLDING, 0.5, 0.5, unseen_s=10.0)
    assert in_the_way(DronePhase.GROUNDED, 0.0, 0.5, unseen_s=10.0)
    assert not in_the_way(DronePhase.PLANNING, 0.2, 0.5)
