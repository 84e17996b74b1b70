"""The training environment's curriculum hook: scene families from the training seed stream, walls included."""

import numpy as np
import pytest

from rpf_fly.learn.env import EnvConfig, SwarmEnv
from rpf_fly.sim.generators import FAMILIES, GeneratorError, generate


def test_curriculum_draws_family_scenes_from_the_training_stream():
    config = EnvConfig(n_arenas=12, curriculum=tuple(FAMILIES), max_steps=50)
    env = SwarmEnv(config, seed=5)
    assert env.obstacles.box_center.shape == (12, 1, max(f.max_boxes for f in FAMILIES.values()))
    seen = set()
    for b in range(12):
        family, seed = env.scene_seeds[b]
        assert env.kinds[b] == family
        seen.add(family)
        scene = generate(family, seed, split="train", n_drones=6)
        assert np.allclose(env.world.position[b], scene.starts) and np.allclose(env.world.goal[b], scene.goals)
        k = scene.obstacles.n_boxes
        assert np.allclose(env.box_center[b, 0, :k], scene.obstacles.box_center)
        bench = generate(family, seed, split="bench", n_drones=6)
        assert not np.allclose(env.world.goal[b], bench.goals)
    assert len(seen) >= 4
    # the walls are obstacles of the observation: every drone of a doorway arena sees one within the arena
    doorway = [b for b in range(12) if env.kinds[b] in ("doorway", "corridor", "u-trap", "passage")]
    assert doorway and (env.nearest.distance[doorway] < 12).all()
    action = np.tile([0.05, 2.0], (12, 6, 1))
    finished = []
    for _ in range(60):
        finished += env.step(action).episodes
    assert finished and {e.arena_kind for e in finished} <= set(FAMILIES)
    assert all(s is not None for s in env.scene_seeds)


def test_without_a_curriculum_the_paper_arenas_are_unchanged():
    plain = SwarmEnv(EnvConfig(n_arenas=4), seed=1)
    assert plain.obstacles.n_boxes == 0 and set(plain.kinds) <= {"a", "b"}
    assert plain.scene_seeds == [None] * 4


def test_unknown_family_is_refused():
    with pytest.raises(GeneratorError):
        SwarmEnv(EnvConfig(n_arenas=2, curriculum=("maze",)), seed=0)


def test_guidance_on_family_scenes_with_walls():
    """Guided training on the families (boxes padded like the circles): the env's waypoints are the planner's."""
    import numpy as np
    import pytest

    from rpf_fly.planning import FixedGains, ObstacleSet, Planner, views_from_states

    env = SwarmEnv(EnvConfig(n_arenas=6, curriculum=tuple(FAMILIES), guidance="path", margin=0.05), seed=4)
    w = env.world
    guided = 0
    for b in range(env.config.n_arenas):
        m = int((env.centers[b, 0].real < 1e5).sum())
        k = int((env.box_center[b, 0].real < 1e5).sum()) if env.box_center.ndim == 3 else 0
        obstacles = (
            ObstacleSet(
                env.centers[b, 0, :m],
                env.radii[b, 0, :m],
                env.box_center[b, 0, :k],
                env.box_half_x[b, 0, :k],
                env.box_half_y[b, 0, :k],
            )
            if k
            else ObstacleSet(env.centers[b, 0, :m], env.radii[b, 0, :m], np.zeros(0, complex), np.zeros(0), np.zeros(0))
        )
        bounds = ((w._lo_x[b, 0], w._hi_x[b, 0]), (w._lo_y[b, 0], w._hi_y[b, 0]))
        planner = Planner(obstacles, env.planner, FixedGains(), bounds)
        step = planner.step(views_from_states(w.position[b], w.velocity[b], w.goal[b], w.heading[b], 6.0))
        waypoint = step.waypoint if step.waypoint is not None else w.goal[b]
        assert env.view.goal[b] == pytest.approx(waypoint, abs=1e-12)
        guided += int((env.view.goal[b] != w.goal[b]).sum())
    assert guided > 0
