"""The ORCA baseline: half-planes worked by hand, the linear programs, encounters, and the planner interface."""

import math
from pathlib import Path

import numpy as np
import pytest

from rpf_fly.planning import ObstacleSet, PlannerConfig, view_of_drone, views_from_states
from rpf_fly.planning.orca import OrcaPlanner, orca_half_plane, solve_velocity, wall_half_plane
from rpf_fly.sim import circle_swap, compute_metrics, make_scenario, rollout
from rpf_fly.sim.rollout import SimParams

ROOT = Path(__file__).resolve().parents[2]
R = 0.1  # safety radius: a collision is d < 2r between drones, d_o < r to an obstacle


def run(scenario, planner, time_limit=60.0):
    params = SimParams(time_limit_s=time_limit)
    result = rollout(scenario, planner, params)
    metrics = compute_metrics(
        result.positions, scenario.goals, params.dt, params.goal_tolerance, R, scenario.obstacles, scenario.names
    )
    return result, metrics


# -- half-planes -----------------------------------------------------------------------------------------------------


def test_half_plane_head_on_projects_onto_the_right_leg():
    """A at the origin flying +x at 0.5 m/s, B 2 m ahead flying -x at 0.5 m/s, combined radius 0.5, tau 4 s.

    By hand: relative velocity v = 1 (x), w = v - p/tau = 0.5 lies inside the cone on its axis, beyond the cut-off
    disc (w . p > 0), so the nearest boundary is a leg; on the axis (cross = 0) the right leg, at angle
    -alpha with sin(alpha) = R/|p| = 0.25. Its outward normal is (-sin a, -cos a); the distance from v to that leg
    is |v| sin(alpha) = 0.25, so u = 0.25 n, and with responsibility 0.5 the half-plane passes through v_A + u/2.
    """
    point, normal = orca_half_plane(2.0 + 0j, 1.0 + 0j, 0.5, 4.0, 0.1, 0.5, 0.5 + 0j)
    s, c = 0.25, math.sqrt(1 - 0.25**2)
    expected_normal = complex(-s, -c)
    assert normal == pytest.approx(expected_normal, abs=1e-12)
    assert point == pytest.approx(0.5 + 0.5 * 0.25 * expected_normal, abs=1e-12)
    assert point == pytest.approx(0.46875 - 0.12103072956898178j, abs=1e-12)
    # A's current velocity is forbidden; turning right (toward -y) at the same speed is allowed.
    assert (0.5 - point).real * normal.real + (0.5 - point).imag * normal.imag < 0
    turn = 0.5 * complex(math.cos(-0.6), math.sin(-0.6))
    assert (turn - point).real * normal.real + (turn - point).imag * normal.imag > 0


def test_half_plane_cut_off_disc_and_static_responsibility():
    """B (static) 1 m ahead, A closing at 0.4 m/s, R 0.5, tau 2: w = 0.4 - 0.5 = -0.1 points back at the apex
    well within the tangent angle, so the cut-off disc (centre 0.5, radius 0.25) is nearest: u = (0.25 - 0.1)(-1)
    and, taking full responsibility, A may close at most at 0.4 - 0.15 = 0.25 m/s."""
    point, normal = orca_half_plane(1.0 + 0j, 0.4 + 0j, 0.5, 2.0, 0.1, 1.0, 0.4 + 0j)
    assert normal == pytest.approx(-1.0 + 0j, abs=1e-12)
    assert point == pytest.approx(0.25 + 0j, abs=1e-12)


def test_half_plane_when_overlapping_leaves_within_one_step():
    """Discs overlapping by 0.1 m, no relative motion: the cut-off disc uses the step dt as horizon, so the drone
    must leave the overlap within one step."""
    point, normal = orca_half_plane(0.4 + 0j, 0j, 0.5, 5.0, 0.1, 1.0, 0j)
    # w = -p/dt = -4, |w| = 4, u = (0.5/0.1 - 4) * (-1) = -1: move away at 1 m/s (more than the speed disc allows).
    assert normal == pytest.approx(-1.0 + 0j)
    assert point == pytest.approx(-1.0 + 0j)


def test_wall_half_plane():
    point, normal = wall_half_plane(1j, 0.6, 0.2, 2.0)  # wall below, 0.6 m away: may approach at 0.2 m/s
    assert normal == 1j and point == pytest.approx(-0.2j)


# -- linear programs -------------------------------------------------------------------------------------------------


def test_lp_returns_the_preferred_velocity_when_unconstrained():
    assert solve_velocity([], 0, 0.5, 0.3 + 0.1j) == 0.3 + 0.1j
    slack = [(-0.4 + 0j, 1.0 + 0j), (0.45j, -1j)]  # v.x >= -0.4 and v.y <= 0.45: both met by the preferred one
    assert solve_velocity(slack, 0, 0.5, 0.3 + 0.1j) == 0.3 + 0.1j
    assert solve_velocity([], 0, 0.5, 3.0 + 4.0j) == pytest.approx(0.3 + 0.4j)  # clipped to the speed disc


def test_lp_projects_onto_a_binding_half_plane():
    v = solve_velocity([(0.1 + 0j, -1.0 + 0j)], 0, 0.5, 0.4 + 0.2j)  # v.x <= 0.1
    assert v == pytest.approx(0.1 + 0.2j)
    v = solve_velocity([(0.1 + 0j, -1.0 + 0j), (0.3j, -1j)], 0, 0.5, 0.4 + 0.4j)  # and v.y <= 0.3: the corner
    assert v == pytest.approx(0.1 + 0.3j)


def test_lp_infeasible_falls_back_to_the_least_violation():
    opposed = [(0.3 + 0j, 1.0 + 0j), (-0.3 + 0j, -1.0 + 0j)]  # v.x >= 0.3 and v.x <= -0.3
    v = solve_velocity(opposed, 0, 0.5, 0.5 + 0j)
    assert v.real == pytest.approx(0.0, abs=1e-9)  # both violated by 0.3
    v = solve_velocity(opposed, 1, 0.5, -0.5 + 0j)  # the first is hard: met exactly
    assert v.real == pytest.approx(0.3, abs=1e-9)
    assert abs(v) <= 0.5 + 1e-12


# -- encounters ------------------------------------------------------------------------------------------------------


def test_two_drones_head_on_pass_without_collision():
    scenario = make_scenario("head-on", np.array([-2.0 + 0j, 2.0]), np.array([2.0 + 0j, -2.0]))
    result, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig()))
    assert metrics.success and metrics.collisions_drone_drone == 0
    assert metrics.min_separation_m >= 2 * R + 0.04
    # Each veers to its own right (the tie takes the right leg of the cone): drone 0 (flying +x) dips to -y.
    assert result.positions[:, 0].imag.min() < -0.05 and result.positions[:, 1].imag.max() > 0.05
    assert metrics.travel_distance_m < 4.2


def test_drone_flies_around_a_pillar_without_entering_it():
    pillar = (_circle((0.0, 0.0), 0.5),)
    scenario = make_scenario("pillar", np.array([-2.0 + 0.05j]), np.array([2.0 + 0j]), shapes=pillar)
    _, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig()))
    assert metrics.success
    assert metrics.min_obstacle_clearance_m >= R + 0.04  # r + margin, less rounding
    # Exactly aligned, the nearest exit from the velocity obstacle is straight back (the cut-off disc): ORCA has
    # no side preference for a static obstacle, so the drone slows to a stop in front of it, never inside.
    scenario = make_scenario("aligned", np.array([-2.0 + 0j]), np.array([2.0 + 0j]), shapes=pillar)
    result, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig()), time_limit=30.0)
    assert metrics.reached == 0 and metrics.collisions_drone_obstacle == 0
    assert metrics.min_obstacle_clearance_m >= R + 0.04
    assert abs(result.positions[-1, 0] - result.positions[-11, 0]) < 0.01


def test_drone_stops_at_a_wall_it_cannot_pass_and_slides_along_one_it_can():
    wall = (_box((-3.0, 0.5), (3.0, 0.7)),)
    # Goal straight behind a wide wall: ORCA's closest permitted velocity is zero: it stops in front, never inside.
    scenario = make_scenario("wall", np.array([0.0 - 1.0j]), np.array([0.0 + 2.0j]), shapes=wall)
    result, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig()), time_limit=20.0)
    assert metrics.reached == 0 and metrics.collisions_drone_obstacle == 0
    assert metrics.min_obstacle_clearance_m >= R
    final = result.positions[-1, 0]
    assert 0.5 - final.imag == pytest.approx(R + 0.05, abs=0.02)  # parked at r + margin from the face
    assert abs(result.positions[-1, 0] - result.positions[-11, 0]) < 1e-3  # stopped
    # Goal diagonally behind a wall that ends at x = 3: it slides along the face and around the end.
    scenario = make_scenario("slide", np.array([-1.0 - 1.0j]), np.array([4.0 + 2.0j]), shapes=wall)
    result, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig()), time_limit=60.0)
    assert metrics.success and metrics.min_obstacle_clearance_m >= R
    track = result.positions[:, 0]
    along_face = track[(0.5 - track.imag < R + 0.05 + 0.1) & (track.real < 3.0)]
    assert along_face.real.max() - along_face.real.min() > 1.0  # slid along the face within 0.1 m of its standoff


def test_eight_drone_swap_on_3m_circle_with_tau_5(record_property):
    """Measured: makespan 14.7 s, travel 5.98 m (straight 5.9 m to the tolerance), min separation 0.25 m.
    pyrvo's ORCA deadlocks here for tau 1, 2 and 10 (the reference notes); this implementation does not."""
    scenario = circle_swap(8, 3.0)
    result, metrics = run(scenario, OrcaPlanner(scenario.obstacles, PlannerConfig(), time_horizon=5.0), 100.0)
    record_property("makespan_s", metrics.makespan_s)
    record_property("travel_distance_m", metrics.travel_distance_m)
    assert metrics.success and metrics.collisions_drone_drone == 0
    assert metrics.min_separation_m >= 2 * R + 0.04
    assert metrics.travel_distance_m == pytest.approx(5.98, abs=0.1)
    assert metrics.makespan_s == pytest.approx(14.7, abs=2.0)
    assert np.abs(result.direction).max() <= 1.0 + 1e-12


# -- the planner interface -------------------------------------------------------------------------------------------

OBSTACLES = ObstacleSet.from_shapes(
    circles=[((0.5, 0.5), 0.5), ((-2.0, 1.0), 0.1), ((2.5, -2.0), 0.3)],
    boxes=[((-3.0, -3.0), (-1.0, -2.5)), ((1.0, 2.0), (1.2, 3.5))],
)


def test_one_drone_call_equals_batched_call():
    rng = np.random.default_rng(3)
    config = PlannerConfig()
    for _ in range(30):
        n = 7
        positions = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
        goals = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
        velocities = 0.5 * np.exp(1j * rng.uniform(-np.pi, np.pi, n)) * (rng.uniform(size=n) > 0.3)
        headings = np.exp(1j * rng.uniform(-np.pi, np.pi, n))
        batch = OrcaPlanner(OBSTACLES, config).step(views_from_states(positions, velocities, goals, headings, 6.0))
        assert batch.direction.shape == (n,) and np.all(np.abs(batch.direction) <= 1 + 1e-12)
        for i in range(n):
            others = np.delete(np.arange(n), i)
            view = view_of_drone(positions[i], goals[i], headings[i], positions[others], velocities[others], 6.0)
            one = OrcaPlanner(OBSTACLES, config).step(view)
            assert isinstance(one.direction, complex)
            assert one.direction == pytest.approx(batch.direction[i], abs=1e-12)
            assert one.neighbours == batch.neighbours[i]
            assert one.obstacle_distance == pytest.approx(batch.obstacle_distance[i], abs=1e-12)
            assert one.f_a == pytest.approx(batch.f_a[i], abs=1e-12)
            assert one.mode == 0 and math.isnan(one.eta) and math.isnan(one.lam) and one.f_r == 0 and one.f_in == 0


def test_free_drone_flies_straight_at_full_speed_and_does_not_overshoot():
    planner = OrcaPlanner(ObstacleSet.empty(), PlannerConfig())
    empty = np.zeros(0, dtype=complex)
    far = planner.step(view_of_drone(0j, 3 + 4j, 1 + 0j, empty, empty, 6.0))
    assert far.direction == pytest.approx(0.6 + 0.8j) and far.goal_distance == pytest.approx(5.0)
    near = planner.step(view_of_drone(0j, 0.02 + 0j, 1 + 0j, empty, empty, 6.0))
    assert near.direction == pytest.approx(0.02 / 0.1 / 0.5 + 0j)  # reaches the goal in one 0.1 s step


def test_one_drone_step_is_fast():
    import time

    rng = np.random.default_rng(0)
    others = rng.uniform(-3, 3, 7) + 1j * rng.uniform(-3, 3, 7)
    velocities = 0.5 * np.exp(1j * rng.uniform(-np.pi, np.pi, 7))
    view = view_of_drone(0j, 3 + 3j, 1 + 0j, others, velocities, 6.0)
    planner = OrcaPlanner(OBSTACLES, PlannerConfig())
    planner.step(view)
    start = time.perf_counter()
    for _ in range(200):
        planner.step(view)
    assert (time.perf_counter() - start) / 200 < 1e-3


def test_planner_kind_orca_flies_the_paper_missions():
    from rpf_fly.mission import load_mission
    from rpf_fly.planning.factory import make_planner
    from rpf_fly.sim.evaluate import evaluate_mission, planner_settings

    assert isinstance(make_planner(planner_settings("orca"), OBSTACLES), OrcaPlanner)
    for name in ("lab-3", "circle-8-r3"):
        (run_,) = evaluate_mission(load_mission(ROOT / "missions" / f"{name}.yaml"), "orca", None, [0])
        assert run_.metrics.success, name


def _circle(center, radius):
    from rpf_fly.mission.model import CircleObstacle

    return CircleObstacle(center, radius)


def _box(lo, hi):
    from rpf_fly.mission.model import BoxObstacle

    return BoxObstacle(lo, hi)
