"""Guidance on a curriculum of walled families: the per-arena corner arrays hold circles' polygons and boxes'
corners."""

import numpy as np
import pytest

from rpf_fly.learn.env import EnvConfig, SwarmEnv
from rpf_fly.planning import FixedGains, Planner, views_from_states
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.visibility import CIRCLE_SIDES
from rpf_fly.sim.generators import FAMILIES, generate


def test_guided_curriculum_with_walls_sizes_its_nodes_and_steps_the_guided_planner():
    families = ("corridor", "pillars", "u-trap", "passage")
    env = SwarmEnv(EnvConfig(n_arenas=6, curriculum=families, guidance="path", margin=0.05, max_steps=40), seed=2)
    m = max(FAMILIES[f].max_circles for f in families)
    k = max(FAMILIES[f].max_boxes for f in families)
    assert env.node.shape == (6, 1, m * CIRCLE_SIDES + 4 * k)
    walled = [b for b in range(6) if env.kinds[b] != "pillars"]
    assert walled
    action = np.tile([0.05, 2.0], (6, 6, 1))
    for _ in range(5):
        env.step(action)
    w = env.world
    for b in walled:
        family, seed = env.scene_seeds[b]
        scene = generate(family, seed, split="train", n_drones=6)
        n = scene.obstacles.n_boxes
        obstacles = ObstacleSet(
            np.zeros(0, complex),
            np.zeros(0),
            env.box_center[b, 0, :n],
            env.box_half_x[b, 0, :n],
            env.box_half_y[b, 0, :n],
        )
        planner = Planner(obstacles, env.planner, FixedGains(0.05, 2.0), (scene.arena_x, scene.arena_y))
        step = planner.step(views_from_states(w.position[b], w.velocity[b], w.goal[b], w.heading[b], 6.0))
        assert env.view.goal[b] == pytest.approx(step.waypoint, abs=1e-9)
    assert (env.view.goal[walled] != w.goal[walled]).any()  # a wall hides some drone's goal
