"""Global guidance: the visibility test, the shortest path around inflated obstacles, the next visible waypoint."""

import math

import numpy as np
import pytest

from rpf_fly.planning import FixedGains, ObstacleSet, Planner, PlannerConfig, build_observation, views_from_states
from rpf_fly.planning.forces import inter_robot, perceived, repulsive
from rpf_fly.planning.guidance import Guidance, path_length
from rpf_fly.planning.obstacles import nearest_obstacle
from rpf_fly.planning.visibility import Inflated, blocked

U_TRAP = ObstacleSet.from_shapes(
    boxes=[((0.0, -1.0), (0.2, 1.0)), ((-1.4, 0.8), (0.2, 1.0)), ((-1.4, -1.0), (0.2, -0.8))]
)
MIXED = ObstacleSet.from_shapes(
    circles=[((0.5, 0.5), 0.5), ((-2.0, 1.0), 0.1), ((2.5, -2.0), 0.3)],
    boxes=[((-3.0, -3.0), (-1.0, -2.5)), ((1.0, 2.0), (1.2, 3.5))],
)


def test_segment_against_a_circle_and_a_box_by_hand():
    inf = Inflated.of(ObstacleSet.from_shapes(circles=[((0.0, 0.0), 0.5)], boxes=[((2.0, -1.0), (3.0, 1.0))]), 0.1)
    # through the circle (radius 0.6), grazing outside it, and through the box grown to x [1.9, 3.1]
    assert blocked(-1 + 0j, 1 + 0j, inf)
    assert not blocked(-1 + 0.61j, 1 + 0.61j, inf)
    assert blocked(1.5 + 0j, 3.5 + 0.5j, inf)
    assert not blocked(1.5 + 1.2j, 3.5 + 1.2j, inf)  # above the grown box (y <= 1.1)
    assert not blocked(1.8 - 2j, 1.8 + 2j, inf)  # beside it
    # a segment that starts inside an inflated obstacle ignores that one (the drone sees its way out)
    assert not blocked(0.55 + 0j, 1.5 + 0j, inf)
    assert not blocked(0.55 + 0j, -1.5 + 0j, inf)  # out through the far side is out too


def test_u_trap_path_goes_out_of_the_mouth_and_around():
    """From inside the U the shortest path leaves by the mouth (x = -1.4 - delta) and passes the outer corner; its
    length is the sum of the legs between the grown boxes' corners."""
    delta = 0.15
    g = Guidance(U_TRAP, delta, ((-3.5, 3.5), (-2.5, 2.5)))
    path = g.path(-0.5 + 0j, 2.2 + 0j)
    corners = [
        complex(-1.4 - delta, -0.8 + delta),
        complex(-1.4 - delta, -1.0 - delta),
        complex(0.2 + delta, -1.0 - delta),
    ]
    mirrored = [c.conjugate() for c in corners]
    inner = path[1:-1]
    assert len(inner) == 3
    assert np.allclose(inner, corners, atol=1e-5) or np.allclose(inner, mirrored, atol=1e-5)
    expected = path_length([-0.5 + 0j, *corners, 2.2 + 0j])
    assert path_length(path) == pytest.approx(expected, abs=1e-5)
    # outside the mouth, straight ahead of it, the goal is still hidden and the path leads around an arm
    w, remaining = g.waypoint(-2.5 + 0j, 2.2 + 0j)
    assert abs(w.imag) > 1.0 and remaining > abs(2.2 + 2.5)


def test_goal_in_sight_is_the_waypoint():
    g = Guidance(MIXED, 0.15)
    w, remaining = g.waypoint(-4 + 0j, -4 + 2j)
    assert w == -4 + 2j and remaining == pytest.approx(2.0)


def test_one_drone_call_equals_batched_call():
    """The flight's one-drone path (plain Python, early exit) and the batched numpy path pick the same waypoint."""
    rng = np.random.default_rng(5)
    g = Guidance(MIXED, 0.15, ((-4.0, 4.0), (-4.0, 4.0)))
    pos = rng.uniform(-4, 4, 300) + 1j * rng.uniform(-4, 4, 300)
    goals = rng.uniform(-4, 4, 300) + 1j * rng.uniform(-4, 4, 300)
    w, r = g.waypoint(pos, goals)
    one = [g.waypoint(complex(p), complex(q)) for p, q in zip(pos, goals)]
    assert np.allclose(w, [o[0] for o in one], atol=1e-12)
    assert np.allclose(r, [o[1] for o in one], atol=1e-9)
    assert np.mean(w != goals) > 0.2  # the test sees both cases


def test_remaining_length_is_never_shorter_than_straight_and_paths_stay_out():
    rng = np.random.default_rng(8)
    g = Guidance(MIXED, 0.15)
    inf = Inflated.of(MIXED, 0.15 - 1e-6)
    for _ in range(30):
        p, q = (complex(*rng.uniform(-4, 4, 2)) for _ in range(2))
        if min(MIXED.signed_distance(np.array([p, q]))) < 0.2:
            continue
        path = g.path(p, q)
        assert path_length(path) >= abs(q - p) - 1e-9
        assert not blocked(np.array(path[:-1]), np.array(path[1:]), inf).any()


def test_planner_guidance_is_off_unless_asked():
    assert Planner(MIXED, PlannerConfig.robust()).guidance is None
    assert Planner(MIXED, PlannerConfig.paper()).guidance is None
    assert Planner(ObstacleSet.empty(), PlannerConfig.robust(guidance="path")).guidance is None
    assert Planner(MIXED, PlannerConfig.robust(guidance="path")).guidance is not None


def test_guided_planner_pulls_toward_the_waypoint():
    planner = Planner(U_TRAP, PlannerConfig.robust(guidance="path", margin=0.05), FixedGains())
    pos = np.array([-0.5 + 0j])
    view = views_from_states(pos, np.zeros(1, complex), np.array([2.2 + 0j]), np.array([1 + 0j]), 6.0)
    step = planner.step(view)
    w, _ = planner.guidance.waypoint(pos, np.array([2.2 + 0j]))
    assert step.waypoint[0] == w[0]
    assert step.f_a[0] == pytest.approx((w[0] - pos[0]) / abs(w[0] - pos[0]))
    assert step.goal_distance[0] == pytest.approx(2.7)


def test_margin_shifts_every_distance_the_forces_see():
    """With margin m the repulsion and the inter-robot coefficient at distance d equal those at d - m without it."""
    m = 0.05
    with_margin = PlannerConfig.robust(margin=m)
    without = PlannerConfig.robust()
    pos = np.array([0.9 + 0.1j, -1.5 + 0.2j])
    nearest = nearest_obstacle(pos, MIXED)
    shifted = type(nearest)(nearest.distance - m, nearest.normal)
    assert np.array_equal(
        repulsive(perceived(nearest, with_margin), 0.05, with_margin), repulsive(shifted, 0.05, without)
    )
    assert perceived(nearest, without) is nearest
    me, other = 0j, np.array([[0.4 + 0.3j]])
    f_m, _ = inter_robot(np.array([me]), other, np.array([[True]]), 2.0, with_margin)
    # the same force at distance 0.5 - m, along the true direction
    f_0, _ = inter_robot(np.array([me]), other * (0.5 - m) / 0.5, np.array([[True]]), 2.0, without)
    assert f_m[0] == pytest.approx(f_0[0])


def test_observation_sees_the_margin():
    m = 0.05
    pos = np.array([0.9 + 0.1j, 1.5 + 0.1j])
    view = views_from_states(pos, np.array([0.5, 0.5 + 0j]), np.array([3 + 0j, 3 + 1j]), np.array([1, 1 + 0j]), 6.0)
    nearest = nearest_obstacle(pos, MIXED)
    o0 = build_observation(view, nearest, PlannerConfig.robust(), 4)
    om = build_observation(view, nearest, PlannerConfig.robust(margin=m), 4)
    assert np.allclose(om.local[:, 0], o0.local[:, 0] - m, atol=1e-6)
    assert np.allclose(om.neighbours[:, 0, 0], o0.neighbours[:, 0, 0] - m, atol=1e-6)
    assert np.array_equal(om.local[:, 1:], o0.local[:, 1:])
    assert math.isclose(float(o0.neighbours[0, 0, 0]), 0.6, abs_tol=1e-6)


# A wall at x = 0 with two gaps: A at y in [-0.5, 0.5] (straight between start and goal) and B at y in [1.5, 2.5].
TWO_GAPS = ObstacleSet.from_shapes(
    boxes=[((-0.1, -3.5), (0.1, -0.5)), ((-0.1, 0.5), (0.1, 1.5)), ((-0.1, 2.5), (0.1, 3.5))]
)
GAPS_BOUNDS = ((-3.0, 3.0), (-3.5, 3.5))


def _parked(*points: complex, moving: bool = False) -> tuple[np.ndarray, np.ndarray]:
    positions = np.array(points, dtype=complex)
    return positions, np.full(positions.shape, not moving)


def test_a_drone_parked_in_the_gap_on_the_way_is_routed_around():
    """Parked in gap A (its disc grown to r + clearance + r + margin = 0.35 m meets the walls grown by 0.15 m), it
    closes the map's straight path: the waypoint leads through gap B, and the remaining length is the longer way."""
    g = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.2)
    start, goal = -2.0 + 0j, 2.0 + 0j
    assert g.waypoint(start, goal) == (goal, pytest.approx(4.0))
    w, remaining = g.waypoint(start, goal, _parked(0j))
    assert 1.5 < w.imag < 2.5 and abs(w.real) < 0.3
    assert remaining == pytest.approx(2 * abs(complex(1.75, 1.65)) + 0.5, abs=0.01)  # by the corners of gap B
    # a neighbour that moves, or none, leaves the map's path; so does a guidance without a parked radius
    assert g.waypoint(start, goal, _parked(0j, moving=True))[0] == goal
    assert Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS).waypoint(start, goal, _parked(0j))[0] == goal
    # parked well off the way (behind the start): the map's path, and no detour graph is built for it
    fresh = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.2)
    assert fresh.waypoint(start, goal, _parked(-2.8 - 2.8j))[0] == goal
    assert fresh.detours_built == 0


def test_the_detour_holds_once_the_leg_in_front_is_clear():
    """On the way to gap B the leg in front of the drone no longer passes the parked drone, but the rest of the map's
    path from there would still go back through gap A: the drone keeps flying toward B, not back into A."""
    g = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.2)
    goal, parked = 2.0 + 0j, _parked(0j)
    p = -2.0 + 0j
    for _ in range(60):  # follow the waypoints in 0.1 m steps until past the wall
        w, _ = g.waypoint(p, goal, parked)
        p = p + 0.1 * (w - p) / abs(w - p) if abs(w - p) > 0.1 else w
        assert not (abs(p.real) < 0.3 and abs(p.imag) < 0.5), f"back into gap A at {p}"
        if p.real > 0.3:
            break
    assert p.real > 0.3 and p.imag > 1.0


def test_no_way_round_the_parked_drones_keeps_the_maps_path():
    """Both gaps closed by parked drones: no detour exists, and the drone keeps the map's path (not plain APF at the
    goal behind the wall). A parked radius of 0.3 m: each grown disc overlaps its gap's grown walls by 0.1 m."""
    g = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.3)
    start, goal = -0.5 + 1.0j, 0.5 + 1.0j  # on either side of the wall between the gaps: both ways equally long
    base = g.waypoint(start, goal)
    assert abs(base[0].real) < 0.3 and g.detour([0j, 2.0j]).waypoint(start, goal)[0] == goal  # both gaps closed
    assert g.waypoint(start, goal, _parked(0j, 2.0j)) == base
    assert g.waypoint(start, goal, _parked(0j))[0].imag > 1.5  # one closed: the other one
    assert g.waypoint(start, goal, _parked(2.0j))[0].imag < 0.5


def test_detour_graphs_are_cached_through_a_hover_wobble():
    g = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.2)
    start, goal = -2.0 + 0j, 2.0 + 0j
    for wobble in (0j, 0.004 + 0.003j, -0.003 + 0.002j, 0.002 - 0.004j):
        w, _ = g.waypoint(start, goal, _parked(0.01 + 0.01j + wobble))
        assert w.imag > 1.5
    assert g.detours_built == 1


def test_detour_one_drone_call_equals_batched_call():
    """Random drones with random parked neighbours: the flight's one-drone path and the batched path agree."""
    rng = np.random.default_rng(11)
    g = Guidance(MIXED, 0.15, ((-4.0, 4.0), (-4.0, 4.0)), parked_radius=0.2)
    n, k = 200, 3
    pos = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
    goals = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
    # neighbours near the straight line between start and goal, so that many of them are in the way
    along = rng.uniform(0.2, 0.8, (n, k))
    others = (
        pos[:, None] + along * (goals - pos)[:, None] + 0.3 * (rng.normal(size=(n, k)) + 1j * rng.normal(size=(n, k)))
    )
    mask = rng.random((n, k)) < 0.7
    w, r = g.waypoint(pos, goals, (others, mask))
    one = [g.waypoint(complex(p), complex(q), (o, m)) for p, q, o, m in zip(pos, goals, others, mask)]
    assert np.allclose(w, [o[0] for o in one], atol=1e-12)
    assert np.allclose(r, [o[1] for o in one], atol=1e-9)
    plain, _ = g.waypoint(pos, goals)
    assert np.mean(w != plain) > 0.2  # the parked drones changed many waypoints
    assert g.detours_built > 10


def test_no_way_at_the_wide_radius_tries_the_drones_bodies_before_giving_up():
    """Both gaps closed by parked drones at the wide radius (0.3 m, grown 0.45) but open at the body radius (0.1 m,
    grown 0.25: a 0.1 m band beside each parked drone): the detour at the body radius leads past the parked drone in
    gap A, not straight through it (the map's path) and not nowhere."""
    start, goal, others = -2.0 + 0j, 2.0 + 0j, [0j, 2.0j]
    wide_only = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.3)
    assert wide_only._detour_one(start, goal, goal, others) is None
    g = Guidance(TWO_GAPS, 0.15, GAPS_BOUNDS, parked_radius=0.3, parked_min_radius=0.1)
    w, remaining = g._detour_one(start, goal, goal, others)
    assert w != goal and abs(w.real) <= 0.26 and 0.25 <= abs(w.imag) <= 0.35
    assert remaining > 4.0
    assert (w, remaining) == g.detour(others, 0.1).waypoint(start, goal)


def test_detour_graph_equals_the_graph_of_the_grown_obstacles_built_from_scratch():
    """The detour reuses the mission's edges and runs Dijkstra per goal; built from scratch on the mission's
    obstacles plus the parked drones' circles (all pairs), the same waypoints and lengths come out."""
    from rpf_fly.planning.guidance import PARKED_QUANTUM

    rng = np.random.default_rng(3)
    bounds = ((-4.0, 4.0), (-4.0, 4.0))
    g = Guidance(MIXED, 0.15, bounds, parked_radius=0.2)
    checked = 0
    for _ in range(12):
        parked = [complex(*np.round(rng.uniform(-3.5, 3.5, 2) / PARKED_QUANTUM) * PARKED_QUANTUM) for _ in range(4)]
        detour = g.detour(parked)
        scratch = Guidance(
            ObstacleSet(
                np.concatenate([MIXED.centers, parked]),
                np.concatenate([MIXED.radii, np.full(4, 0.2)]),
                MIXED.box_center,
                MIXED.box_half_x,
                MIXED.box_half_y,
            ),
            0.15,
            bounds,
        )
        pos = rng.uniform(-4, 4, 40) + 1j * rng.uniform(-4, 4, 40)
        goals = rng.uniform(-4, 4, 40) + 1j * rng.uniform(-4, 4, 40)
        w1, r1 = detour.waypoint(pos, goals)
        w2, r2 = scratch.waypoint(pos, goals)
        assert np.allclose(w1, w2, atol=1e-9) and np.allclose(r1, r2, atol=1e-9)
        one = [detour.waypoint(complex(p), complex(q)) for p, q in zip(pos, goals)]
        assert np.allclose(w1, [o[0] for o in one], atol=1e-12)
        checked += int(np.sum(w1 != goals))
    assert checked > 100  # most of them lead round something
