"""rpf_fly/flight/response.py: the ground station's model of how a drone's firmware answers a position setpoint,
against the full model of the firmware's PID cascade on the identified body (rpf_fly/emulator/cf_scenario.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rpf_fly.emulator.cf_scenario import fly, hold_scenario
from rpf_fly.emulator.fake_setpoint import AxisMode, Setpoint
from rpf_fly.emulator.fake_vehicle import Vehicle, VehicleConfig
from rpf_fly.flight.agent import carrot_max_lead_m
from rpf_fly.flight.response import (
    DEFAULT_GAINS,
    POSE_AGE_ALLOWANCE_S,
    Braking,
    Follower,
    ResponseGains,
    braking_for,
    overshoot_m,
    reach_after_death_m,
    respond,
)

REFERENCE = Path(__file__).resolve().parents[1] / "data" / "crazyflie_dynamics"  # ../shared/reference, copied


@pytest.mark.parametrize("speed", [0.3, 0.45, 0.7, 1.0])
def test_a_hold_where_the_drone_is_overshoots_as_the_full_model_does(speed: float) -> None:
    full = fly(hold_scenario(speed, duration_s=6.0))["figures"]["overshoot_cm"] / 100.0
    reduced = overshoot_m(DEFAULT_GAINS, speed)
    assert abs(reduced - full) <= max(0.01, 0.1 * full), (speed, reduced, full)


def test_a_steady_carrot_is_trailed_by_speed_over_gain_and_the_drag() -> None:
    """Chasing a setpoint that moves at v, the drone settles v / posCtlPid.xKp behind it, plus what holding its
    speed against drag costs the velocity loop (the reference's 27 cm at 0.5 m/s)."""
    for speed, reference in ((0.5, 0.27), (1.0, 0.56)):
        steps = np.arange(800)  # 8 s at 100 Hz, the carrot streamed at 10 Hz
        carrot = np.stack([speed * 0.1 * (steps // 10 + 1), np.zeros(len(steps))], axis=1)
        track = respond(DEFAULT_GAINS, np.zeros(2), np.zeros(2), carrot, 8.0)
        lag = np.mean(carrot[-200:, 0] - 0.05 * speed - track[-200:, 0])  # against the carrot's mean over a period
        assert abs(lag - reference) <= 0.2 * reference, (speed, lag)


def test_the_gains_come_from_the_drones_parameters() -> None:
    soft = ResponseGains.from_params(
        {"posCtlPid.xKp": 1.0, "velCtlPid.vxKp": 12.5, "posCtlPid.pLimit": 10.0, "unrelated.param": 3.0}
    )
    assert (soft.pos_kp, soft.vel_kp, soft.tilt_limit_deg, soft.vel_ki) == (1.0, 12.5, 10.0, DEFAULT_GAINS.vel_ki)
    assert braking_for(None).gains == DEFAULT_GAINS
    # a 10 degree tilt limit brakes at half the deceleration: the drone needs further to stop
    assert braking_for({"posCtlPid.pLimit": 10.0}).stop_m(0.8) > 1.3 * braking_for(None).stop_m(0.8)
    assert braking_for({"posCtlPid.pLimit": 10.0}) is braking_for({"posCtlPid.pLimit": 10.0})  # one table


def test_the_stop_grows_with_the_speed_and_is_no_further_than_holding_where_it_was() -> None:
    braking = Braking()
    speeds = [0.1, 0.3, 0.5, 0.7, 1.0, 1.3]
    stops = [braking.stop_m(v) for v in speeds]
    assert stops == sorted(stops) and stops[0] < 0.03 and 0.2 < braking.stop_m(1.0) < 0.35
    for v in speeds:
        assert braking.stop_m(v) <= overshoot_m(DEFAULT_GAINS, v) + 0.006
    assert braking.stop_m(2.0) > braking.stop_m(1.5)  # beyond the table: grows with the square
    assert braking.stop_m(0.0) == 0.0


def test_the_hold_point_lies_along_the_drones_way_and_brings_it_to_rest_there() -> None:
    braking = Braking()
    at, velocity = 1.0 + 2.0j, 0.0 + 1.0j  # flying +y at 1 m/s
    hold = braking.hold_point(at, velocity)
    assert hold.real == pytest.approx(1.0) and abs(hold.imag - 2.0) <= braking.stop_m(1.0)
    assert braking.hold_point(at, 0j) == at
    # flown on the model: the drone comes to rest within the stop distance of where it was, past no further
    track = respond(DEFAULT_GAINS, np.array([1.0, 2.0]), np.array([0.0, 1.0]), np.array([hold.real, hold.imag]), 4.0)
    assert track[:, 1].max() - 2.0 <= braking.stop_m(1.0) + 1e-9
    # at rest after 4 s, near the hold point (the velocity integrator, wound up against drag, unwinds slowly)
    assert abs(track[-1, 1] - track[-2, 1]) / 0.01 < 0.05 and abs(track[-1, 1] - hold.imag) < 0.05
    assert abs(track[-1, 0] - 1.0) < 1e-6


@pytest.mark.parametrize("name", ["c_carrot_0p5", "c_carrot_1p0", "p_hold_0p3", "p_circle_r0p5_v0p3"])
def test_a_drones_setpoint_is_where_its_speed_and_acceleration_put_it(name: str) -> None:
    """Against the dynamics reference's traces (the firmware's cascade on the identified body, not this project's
    model): predicted from its position, velocity and acceleration with `steady_lag_s` and `acceleration_lead_s2`,
    a drone's setpoint is found twice as near as from its velocity alone while the drone speeds up or brakes: what
    a neighbour's planner needs (`DroneAgent.predict`)."""
    doc = json.loads((REFERENCE / "traces" / f"{name}.json").read_text())
    t, setpoint, position = np.array(doc["t"]), np.array(doc["sp"])[:, :2], np.array(doc["pos"])[:, :2]
    velocity = np.gradient(position, t, axis=0)
    acceleration = np.gradient(velocity, t, axis=0)
    by_speed = position + DEFAULT_GAINS.steady_lag_s * velocity
    with_acceleration = by_speed + DEFAULT_GAINS.acceleration_lead_s2 * acceleration
    changing = np.linalg.norm(acceleration, axis=1) > 0.3
    assert changing.sum() > 20
    before = np.linalg.norm(setpoint - by_speed, axis=1)
    after = np.linalg.norm(setpoint - with_acceleration, axis=1)
    assert after[changing].mean() < 0.6 * before[changing].mean(), (after[changing].mean(), before[changing].mean())
    assert after.mean() < before.mean()
    assert DEFAULT_GAINS.acceleration_lead_s2 == pytest.approx(1 / (2.0 * 9.81 * np.radians(25.0)))


def _after_death_m(speed: float, lead: float, backwards: bool, height: float = 0.66) -> float:
    """The full model (rpf_fly/emulator/fake_vehicle.py: the PID cascade, the identified body, the supervisor's
    watchdogs): a drone flies a 10 Hz carrot at ``speed`` along +x (``backwards``: along -x), is sent one setpoint
    ``lead`` ahead along +x, and then nothing more (its ground station died; no ping feeds its emergency-stop
    watchdog): how far it goes horizontally, until it lies on the floor."""
    abs3 = (AxisMode.ABS, AxisMode.ABS, AxisMode.ABS)
    drone = Vehicle(VehicleConfig(dynamics="firmware", turbulence_m_s2=0.0), 0.0)
    ref, sign, t, k = 0.0, -1.0 if backwards else 1.0, 0.0, 0

    def send(x: float) -> None:
        drone.crtp_setpoint(Setpoint(abs3, (x, 0.0, height), yaw_mode=AxisMode.ABS, timestamp_s=t, source="crtp-7"), t)

    while t < 5.0:  # 2 s to hover, 3 s on the carrot
        if k % 10 == 0:
            if t >= 2.0:
                ref += sign * speed * 0.1
            send(ref)
        drone.supervisor.notify_emergency_stop_watchdog(t)
        drone.step(t)
        k += 1
        t = k * 0.001
    start = drone.pos[0]
    send(start + lead)
    while t < 8.0:
        drone.step(t)
        k += 1
        t = k * 0.001
    assert drone.pos[2] < 0.01 and not drone.motors_on  # it fell and lies there
    return abs(drone.pos[0] - start)


@pytest.mark.parametrize("speed", [0.3, 0.5, 1.0])
def test_a_drone_whose_ground_station_died_goes_no_further_than_its_reach(speed: float) -> None:
    """`reach_after_death_m` bounds the full model's flight to its last setpoint, its level-out and its fall, for a
    carrot that leads it by the most the agent allows (plus a pose `POSE_AGE_ALLOWANCE_S` old), for a drone flying
    towards it, one flying away from it and one at rest; and it is not loose by more than 60 %."""
    lead = carrot_max_lead_m(speed, DEFAULT_GAINS) + speed * POSE_AGE_ALLOWANCE_S
    moved = [_after_death_m(v, lead, backwards) for v, backwards in ((speed, False), (speed, True), (0.0, False))]
    reach = reach_after_death_m(DEFAULT_GAINS, speed, carrot_max_lead_m(speed, DEFAULT_GAINS), 0.66)
    assert max(moved) <= reach <= 1.6 * max(moved), (speed, moved, reach)


def test_a_coasted_follower_is_the_model_flown_on_and_leaves_the_model_where_it_was():
    """`Follower.coasted` flies a copy on towards a setpoint for whole 10 ms steps (rounded up); the model itself
    stays put: the separation check asks it every frame where a drone will be when a hold reaches it."""
    model = Follower(DEFAULT_GAINS, 0j, 0.2 + 0j)
    model.step(0.3 + 0j, 0.05)
    before = (model.position, model.velocity, model.tilt_deg)
    twin = model.coasted(0.5 + 0j, 0.125)
    assert (model.position, model.velocity, model.tilt_deg) == before
    flown = Follower(DEFAULT_GAINS, 0j, 0.2 + 0j)
    flown.step(0.3 + 0j, 0.05)
    flown.step(0.5 + 0j, 0.13)
    assert (twin.position, twin.velocity, twin.tilt_deg) == (flown.position, flown.velocity, flown.tilt_deg)
    assert twin.velocity.real > model.velocity.real and twin.tilt_deg.real > model.tilt_deg.real  # speeding up
