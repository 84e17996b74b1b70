"""The training environment: same APF as the planner, the paper's reward terms, per-robot termination, resets."""

import numpy as np
import pytest

from rpf_fly.learn.env import EnvConfig, SwarmEnv
from rpf_fly.planning import FixedGains, Planner, views_from_states
from rpf_fly.planning.obstacles import ObstacleSet


def make_env(**overrides):
    return SwarmEnv(EnvConfig(n_arenas=4, **overrides), seed=3)


def gains(env, eta=0.05, lam=2.0):
    a = np.zeros((env.config.n_arenas, env.config.n_robots, 2))
    a[..., 0], a[..., 1] = eta, lam
    return a


def test_env_steps_the_planner_apf():
    """Directions in the env equal Planner.step on one arena's own obstacles (padding changes nothing)."""
    env = make_env(arena="a")
    b = 1
    m = int((env.centers[b, 0].real < 1e5).sum())
    obstacles = ObstacleSet(env.centers[b, 0, :m], env.radii[b, 0, :m], *([np.zeros(0)] * 3))
    obstacles = ObstacleSet(obstacles.centers, obstacles.radii, np.zeros(0, complex), np.zeros(0), np.zeros(0))
    w = env.world
    planner = Planner(obstacles, env.planner, FixedGains(0.04, 1.5))
    expected = planner.step(views_from_states(w.position[b], w.velocity[b], w.goal[b], w.heading[b], 6.0)).direction
    got = env.directions(gains(env, 0.04, 1.5))[b]
    assert got == pytest.approx(expected, abs=1e-12)


def test_guided_env_steps_the_guided_planner():
    """With guidance and margin the env pulls each drone toward the waypoint Planner.step picks (graphs per arena,
    padded), and its observation's d_g is the remaining path length."""
    env = make_env(arena="a", guidance="path", margin=0.05)
    half = env.config.arena_half_size
    w = env.world
    for _ in range(30):
        env.step(gains(env))
    for b in range(env.config.n_arenas):
        m = int((env.centers[b, 0].real < 1e5).sum())
        obstacles = ObstacleSet(
            env.centers[b, 0, :m], env.radii[b, 0, :m], np.zeros(0, complex), np.zeros(0), np.zeros(0)
        )
        planner = Planner(obstacles, env.planner, FixedGains(0.04, 1.5), ((-half, half), (-half, half)))
        step = planner.step(views_from_states(w.position[b], w.velocity[b], w.goal[b], w.heading[b], 6.0))
        assert env.view.goal[b] == pytest.approx(step.waypoint, abs=1e-12)
        assert env.directions(gains(env, 0.04, 1.5))[b] == pytest.approx(step.direction, abs=1e-12)
        _, remaining = planner.guidance.waypoint(w.position[b], w.goal[b])
        assert env.observation.local[b, :, 2] == pytest.approx(remaining.astype(np.float32))
    assert (env.view.goal != w.goal).any()  # some drone is guided around an obstacle


def test_margin_penalty_only_with_a_margin():
    """A drone between r and r + margin of an obstacle pays margin_penalty; the paper's env (margin 0) does not."""
    penalties = []
    for margin in (0.0, 0.05):
        env = make_env(arena="a", margin=margin)
        w = env.world
        c, radius = env.centers[0, 0, 0], env.radii[0, 0, 0]
        # robot 0 of arena 0 held 0.12 m from the surface (r < 0.12 < r + margin; no other term changes)
        w.position[0, 0] = c + (radius + 0.12) * 1j
        w.halted[0, 0] = True
        action = gains(env)
        reward = env.step(action).reward[0, 0]
        penalties.append(reward)
    assert penalties[0] - penalties[1] == pytest.approx(env.config.margin_penalty, abs=1.0)


def test_arrival_reward_and_termination():
    env = make_env(arena="b")
    w = env.world
    # Put robot 0 of arena 0 just short of its goal, heading straight at it.
    w.position[0, 0] = w.goal[0, 0] - 0.12
    w.heading[0, 0] = 1 + 0j
    env.start[0, 0] = w.goal[0, 0] - 4.0
    env.path[0, 0] = 5.0
    env._observe()
    result = env.step(gains(env, lam=0.0))  # no neighbour push: the drone flies straight onto its goal
    assert result.valid[0, 0] and result.done[0, 0]
    # R_m = 300 - 100 * d_a / d_s with d_a = 5 + 0.05, d_s = 4; plus the potential shaping term.
    arrival = 300 - 100 * 5.05 / 4.0
    assert result.reward[0, 0] == pytest.approx(arrival, abs=0.05)
    following = env.step(gains(env))
    assert not following.valid[0, 0] and following.reward[0, 0] == 0


def test_robot_collision_penalty_halts_both():
    env = make_env(arena="b")
    w = env.world
    w.position[0, 1] = w.position[0, 0] + 0.15  # closer than 2r = 0.2 after any move of 0.05
    env._observe()
    result = env.step(gains(env, lam=0.0))
    assert result.done[0, 0] and result.done[0, 1]
    assert result.reward[0, 0] < -450 and result.reward[0, 1] < -450  # collision_penalty 500
    assert w.halted[0, 0] and w.halted[0, 1]
    before = w.position[0, :2].copy()
    env.step(gains(env))
    assert np.all(w.position[0, :2] == before)


def test_obstacle_band_and_turn_penalties():
    env = make_env(arena="a")
    w = env.world
    b, i = 0, 0
    c, rad = env.centers[b, 0, 0], env.radii[b, 0, 0]
    # 0.15 m from the surface (between r and 2r) after moving tangentially: -20.
    w.position[b, i] = c + (rad + 0.15)
    w.heading[b, i] = 1j
    w.goal[b, i] = c + (rad + 0.15) + 3j
    env._observe()
    env.directions(gains(env))
    result = env.step(gains(env))
    assert result.reward[b, i] < -15
    # A heading reversal is a turn of more than 45 degrees: -5 on top.
    env2 = make_env(arena="b")
    env2.world.heading[0, 0] = -env2.world.heading[0, 0]
    env2._observe()
    r2 = env2.step(gains(env2))
    assert r2.reward[0, 0] < -4


def test_arena_resets_when_all_done():
    env = make_env(arena="b")
    old_goals = env.world.goal[2].copy()
    env.done[2] = True
    env.done[2, 0] = False
    env.world.position[2, 0] = env.world.goal[2, 0] - 0.11
    env.world.heading[2, 0] = 1 + 0j
    env._observe()
    result = env.step(gains(env, lam=0.0))
    assert len(result.episodes) == 1
    assert not np.allclose(env.world.goal[2], old_goals)
    assert not env.done[2].any() and env.t[2] == 0


def test_truncation_ends_flying_robots():
    env = SwarmEnv(EnvConfig(n_arenas=2, arena="b", max_steps=3), seed=1)
    results = [env.step(gains(env)) for _ in range(3)]
    assert results[-1].done.all()
    assert sum(len(r.episodes) for r in results) == 2
    assert not any(e.success for r in results for e in r.episodes)


def test_heading_action_turns_left_for_positive_a():
    env = make_env(arena="b", action="heading")
    h = env.world.heading.copy()
    direction = env.directions(np.ones((4, 6, 1)))
    assert direction == pytest.approx((h + 1j * h) / abs(h + 1j * h))
