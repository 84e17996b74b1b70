"""Scenario generators (the paper's arenas A and B) and mission scenarios with seeded jitter."""

import numpy as np
import pytest

from rpf_fly.mission.model import (
    Arena,
    CircleObstacle,
    Drone,
    FlightSettings,
    Formation,
    Mission,
    MocapSettings,
    PlannerSettings,
    RadioSettings,
    SimSettings,
)
from rpf_fly.sim import arena_a, arena_b, scenario_from_mission


def test_arena_a_is_valid_and_seeded():
    a1 = arena_a(np.random.default_rng(11))
    a2 = arena_a(np.random.default_rng(11))
    a3 = arena_a(np.random.default_rng(12))
    assert np.array_equal(a1.starts, a2.starts) and np.array_equal(a1.goals, a2.goals)
    assert not np.array_equal(a1.starts, a3.starts)
    assert a1.n_drones == 6 and len(a1.shapes) == 12
    assert all(s.radius == 0.5 for s in a1.shapes)
    r = 0.1
    assert a1.obstacles.signed_distance(a1.starts).min() >= 2 * r
    assert a1.obstacles.signed_distance(a1.goals).min() >= 2 * r
    assert abs(a1.goals - a1.starts).min() >= 4.0
    gaps = abs(a1.starts[:, None] - a1.starts[None, :]) + np.eye(6) * 99
    assert gaps.min() >= 4 * r
    assert (abs(a1.starts.real) <= 5).all() and (abs(a1.starts.imag) <= 5).all()


def test_arena_b_is_a_jittered_swap():
    b = arena_b(np.random.default_rng(3))
    assert np.allclose(abs(b.starts), 2.0)
    assert np.allclose(b.goals, -b.starts)
    nominal = np.arange(6) * np.pi / 3
    offsets = np.angle(b.starts * np.exp(-1j * nominal))
    assert np.abs(offsets).max() <= np.deg2rad(15) + 1e-12
    assert np.abs(offsets).max() > 0


def swap_mission(angle_jitter=0.0, start_jitter=0.0):
    n, radius = 8, 3.0
    form = Formation("circle_swap", n, radius)
    drones = tuple(
        Drone(
            f"cf{i + 1}",
            f"radio://0/80/2M/E7E7E7E7{i + 1:02X}",
            f"cf{i + 1}",
            (radius * np.cos(2 * np.pi * i / n), radius * np.sin(2 * np.pi * i / n)),
            (-radius * np.cos(2 * np.pi * i / n), -radius * np.sin(2 * np.pi * i / n)),
        )
        for i in range(n)
    )
    return Mission(
        "swap",
        Arena((-4, 4), (-4, 4)),
        FlightSettings(),
        PlannerSettings(),
        MocapSettings(),
        RadioSettings(),
        SimSettings(start_jitter_m=start_jitter, angle_jitter_deg=angle_jitter),
        (CircleObstacle((0, 0), 0.2),),
        drones,
        form,
    )


def test_mission_without_jitter_is_nominal_for_every_seed():
    m = swap_mission()
    s0, s5 = scenario_from_mission(m, 0), scenario_from_mission(m, 5)
    assert np.allclose(s0.starts, s5.starts)
    assert s0.starts[0] == pytest.approx(3 + 0j)
    assert s0.names[0] == "cf1" and len(s0.shapes) == 1


def test_angle_jitter_keeps_swaps_antipodal_and_depends_on_seed():
    m = swap_mission(angle_jitter=5.0)
    s1, s1b, s2 = scenario_from_mission(m, 1), scenario_from_mission(m, 1), scenario_from_mission(m, 2)
    assert np.array_equal(s1.starts, s1b.starts)
    assert not np.allclose(s1.starts, s2.starts)
    assert np.allclose(abs(s1.starts), 3.0) and np.allclose(s1.goals, -s1.starts)
    nominal = 3 * np.exp(2j * np.pi * np.arange(8) / 8)
    assert np.abs(np.angle(s1.starts / nominal)).max() <= np.deg2rad(5) + 1e-12


def test_start_jitter_stays_within_disc():
    m = swap_mission(start_jitter=0.2)
    s = scenario_from_mission(m, 4)
    nominal = 3 * np.exp(2j * np.pi * np.arange(8) / 8)
    moved = abs(s.starts - nominal)
    assert moved.max() <= 0.2 and moved.max() > 0
    assert np.allclose(s.goals, -s.starts)
