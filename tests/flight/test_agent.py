"""DroneAgent: the carrot reference, its lead limit, the geofence and the observed tracking lag."""

from __future__ import annotations

import pytest

from rpf_fly.flight.agent import DroneAgent, PlannerFault
from rpf_fly.mission.model import Arena, Drone
from rpf_fly.planning.planner import PlanStep


class Straight:
    """A planner that always heads +x (the agent under test, not the APF, is what matters here)."""

    def __init__(self, direction: complex = 1 + 0j):
        self.direction = direction

    def step(self, view):  # type: ignore[no-untyped-def]
        return PlanStep(self.direction, 0, 0j, 0j, 0j, 0.0, 0.0, 0, 1.0, 1.0)


def make_agent(planner=None, **kw) -> DroneAgent:  # type: ignore[no-untyped-def]
    drone = Drone(name="cf1", uri="radio://0/80/2M/E7E7E7E701", rigid_body="cf1", start=(0.0, 0.0), goal=(1.5, 0.0))
    arena = Arena(x=(-2.0, 2.0), y=(-2.0, 2.0), z=(0.0, 1.5))
    return DroneAgent(drone, planner or Straight(), height=0.5, speed=0.5, dt=0.1, arena=arena, budget_s=1.0, **kw)


def test_reference_advances_at_mission_speed_and_lag_is_its_lead_over_the_drone():
    agent = make_agent()
    agent.begin_planning(0j, 0.0)
    assert agent.tracking_lag_s(0j) == 0.0
    for _ in range(3):
        result = agent.plan(None, 0j)  # the drone has not moved yet
    assert result.setpoint == pytest.approx(0.15)
    assert agent.tracking_lag_s(0j) == pytest.approx(0.15 / 0.5)
    assert agent.tracking_lag_s(0.1 + 0j) == pytest.approx(0.05 / 0.5)


def test_reference_never_leads_the_drone_by_more_than_max_lead_nor_leaves_the_arena():
    agent = make_agent(max_lead_m=0.2)
    agent.begin_planning(0j, 0.0)
    for _ in range(10):
        agent.plan(None, 0j)
    assert abs(agent.reference) == pytest.approx(0.2)
    assert agent.tracking_lag_s(0j) == pytest.approx(0.2 / 0.5)
    agent.reference = 1.95 + 0j
    assert agent.plan(None, 1.9 + 0j).setpoint == 2.0 + 0j


def test_the_geofence_keeps_the_whole_body_inside_the_arena():
    """A setpoint at the arena's edge would put half the drone outside it: the fence is the arena shrunk by the
    body radius (the mission's safety radius), in x, y and under the ceiling."""
    agent = make_agent(body_radius_m=0.1)
    assert agent.clamp(5 + 5j) == pytest.approx(1.9 + 1.9j)
    assert agent.clamp(-5 - 5j) == pytest.approx(-1.9 - 1.9j)
    assert agent.clamp(0.3 - 0.4j) == 0.3 - 0.4j
    assert agent.clamp_height(1.5) == pytest.approx(1.4)
    agent.begin_planning(1.85 + 0j, 0.0)
    assert agent.plan(None, 1.85 + 0j).setpoint == pytest.approx(1.9 + 0j)


def test_an_invalid_direction_is_this_drones_planner_fault():
    agent = make_agent(Straight(float("nan") + 0j))
    agent.begin_planning(0j, 0.0)
    with pytest.raises(PlannerFault, match="invalid direction"):
        agent.plan(None, 0j)


class Busy(Straight):
    """Computes (burns ``seconds`` of its thread's CPU time, however long a loaded host takes to give it that) or
    waits (sleeps) for ``seconds`` before answering."""

    def __init__(self, seconds: float, compute: bool):
        super().__init__()
        self.seconds, self.compute = seconds, compute

    def step(self, view):  # type: ignore[no-untyped-def]
        import time

        if self.compute:
            end = time.thread_time() + self.seconds
            while time.thread_time() < end:
                pass
        else:
            time.sleep(self.seconds)
        return super().step(view)


def test_a_planner_computing_past_its_budget_is_this_drones_fault():
    agent = make_agent(Busy(0.03, compute=True))
    agent.budget_s = 0.01
    agent.begin_planning(0j, 0.0)
    with pytest.raises(PlannerFault, match="planner took"):
        agent.plan(None, 0j)


def test_waiting_is_not_computing_the_drone_is_not_blamed_for_a_stalled_thread():
    """The budget is CPU time of the loop thread: time spent descheduled or waiting (here: asleep) is not the
    planner's doing (a GIL wait or a pre-emption in flight looks the same to a wall clock)."""
    agent = make_agent(Busy(0.03, compute=False))
    agent.budget_s = 0.01
    agent.begin_planning(0j, 0.0)
    assert agent.plan(None, 0j).setpoint == pytest.approx(0.5 * 0.1)  # one step at the mission speed


def test_the_carrot_may_lead_by_the_drones_steady_lag_at_the_mission_speed():
    """A firmware-default drone trails a moving setpoint by 0.55 s x speed: held within 0.3 m, a 1 m/s mission's
    carrot would cap it at 0.6 m/s. The lead allowed is 1.25 times the steady lag, at least what was given."""
    fast = make_agent()
    fast.speed = 1.0
    fast.set_controller(None)
    assert fast.max_lead_m == pytest.approx(1.25 * 1.0 * 0.5496, abs=0.002)
    slow = make_agent()  # 0.5 m/s: 0.34 m
    assert slow.max_lead_m == pytest.approx(1.25 * 0.5 * 0.5496, abs=0.002)
    stiff = make_agent()
    stiff.set_controller({"posCtlPid.xKp": 4.0})  # a stiffer position loop trails less: never under 0.3 m
    assert stiff.max_lead_m == pytest.approx(0.3)
    fixed = make_agent(max_lead_m=0.2)
    fixed.set_controller(None)
    assert fixed.max_lead_m == 0.2  # a caller's own lead stands


def test_neighbours_are_planned_where_their_setpoints_are_for_the_drones_controller():
    """Ahead of what mocap sees by the firmware cascade's steady lag x their velocity and its
    `acceleration_lead_s2` x their acceleration (both larger for a softer controller); a dry run's first-order
    drone's setpoint leads it by its speed alone, this drone's own observed lag of it."""
    import numpy as np

    agent = make_agent()
    agent.begin_planning(0j, 0.0)
    agent.plan(None, 0j)  # its carrot 0.05 m ahead: a lag of 0.1 s at 0.5 m/s
    xy, velocity, acceleration = np.array([1.0 + 1.0j]), np.array([0.5 + 0j]), np.array([0.0 + 2.0j])
    cascade = agent.predict(xy, velocity, acceleration, 0j)
    assert cascade[0] == pytest.approx(1.0 + 1.0j + 0.5496 * 0.5 + 0.1168 * 2.0j, abs=1e-3)
    assert agent.predict(1.0 + 1.0j, 0.5 + 0j, 2.0j, 0j) == pytest.approx(complex(cascade[0]))  # one drone alike
    soft = make_agent()
    soft.set_controller({"velCtlPid.vxKp": 12.5})
    assert soft.acceleration_lead_s2 == pytest.approx(2 * agent.acceleration_lead_s2)
    first_order = make_agent()
    first_order.set_controller(None, first_order=True)
    first_order.begin_planning(0j, 0.0)
    first_order.plan(None, 0j)
    assert first_order.predict(xy, velocity, acceleration, 0j)[0] == pytest.approx(1.05 + 1.0j)


def test_a_neighbours_setpoint_leads_it_by_the_radios_latency_too():
    """A setpoint reaches its drone as late as the radio budget models its dongle (cflib's shared radio thread, the
    other links' turns): 8 drones on one Crazyradio PA wait longer than 3, and a neighbour is planned ahead of what
    mocap sees by that much more of its velocity (a first-order drone's observed lag has it already)."""
    import numpy as np

    from rpf_fly.flight.agent import link_lags_s
    from rpf_fly.mission import parse_mission
    from rpf_fly.radio.budget import radio_loads

    def mission(n: int):  # type: ignore[no-untyped-def]
        drones = "\n".join(
            f"  - {{name: cf{i}, uri: radio://0/80/2M/E7E7E7E70{i}, start: [{i - 4}.0, -1.0], goal: [{i - 4}.0, 1.0]}}"
            for i in range(1, n + 1)
        )
        return parse_mission(
            "name: m\narena: {x: [-5.0, 5.0], y: [-3.0, 3.0], z: [0.0, 2.0]}\n"
            "flight: {height: 1.0, speed: 0.5, rate_hz: 10}\nmocap: {kind: sim}\n"
            f"radio: {{extpos: packed}}\ndrones:\n{drones}\n"
        )

    three, eight = mission(3), mission(8)
    lags3, lags8 = link_lags_s(three), link_lags_s(eight)
    assert set(lags8) == {f"cf{i}" for i in range(1, 9)}
    assert lags8["cf1"] == radio_loads(eight)[0].setpoint_p50_s
    assert 0.0 < lags3["cf1"] < lags8["cf1"] < 0.1
    agent = DroneAgent.for_mission(eight.drones[0], Straight(), eight)
    assert agent.link_lag_s == lags8["cf1"]
    agent.begin_planning(complex(*eight.drones[0].start), 0.0)
    still = make_agent()
    velocity = np.array([0.5 + 0j])
    ahead = agent.predict(np.array([0j]), velocity, np.array([0j]), complex(*eight.drones[0].start))
    assert ahead[0] - still.predict(np.array([0j]), velocity, np.array([0j]), 0j)[0] == pytest.approx(
        0.5 * lags8["cf1"]
    )
    first_order = DroneAgent.for_mission(eight.drones[0], Straight(), eight)
    first_order.set_controller(None, first_order=True)
    assert first_order.prediction(0j)[0] == first_order.tracking_lag_s(0j)


def test_a_hold_at_speed_brings_the_drone_to_rest_ahead_and_moves_up_as_it_slows():
    agent = make_agent()
    agent.begin_planning(0j, 0.0)
    agent.last_setpoint = 0.55 + 0j  # the carrot ahead of a drone flying +x at 1 m/s
    agent.hold(0j, 1.0, "separation", velocity=1.0 + 0j)
    first = agent.hold_point
    stop = agent.braking.stop_point(0j, 1.0 + 0j, 0.55 + 0j)
    assert abs(first.imag) < 1e-9 and first.real < stop.real  # on its way, short of where it stops
    agent.refine_hold(0.2 + 0j, 0.4 + 0j)  # braked to 0.4 m/s 0.2 m on
    assert first.real < agent.hold_point.real <= stop.real + 1e-9
    before = agent.hold_point
    agent.refine_hold(0.25 + 0j, -0.1 + 0j)  # turned back: the point stays
    assert agent.hold_point == before
    agent.last_setpoint = 0j
    agent.hold(0j, 2.0, "separation")  # at rest where it was told to be: there
    assert agent.hold_point == 0j
    agent.last_setpoint = 0.55 + 0j
    agent.hold(0j, 3.0, "separation")  # at rest, but asked ahead (tilting to go): a little behind, against it
    assert -0.1 < agent.hold_point.real < 0.0
