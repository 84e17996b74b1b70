"""Pure planning functions over numpy arrays: APF forces, wall-following, soft rule, views, observations, gains.

No sockets, threads, clocks or torch here (docs/architecture.md): the simulator, the trainer and the flight loop
all call the same :class:`Planner`.
"""

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.gains import FixedGains, GainsPolicy
from rpf_fly.planning.observation import Observation, build_observation
from rpf_fly.planning.obstacles import FAR, NearestObstacle, ObstacleSet, nearest_obstacle
from rpf_fly.planning.planner import Planner, PlanStep, apf_step, sense_obstacles
from rpf_fly.planning.view import LocalView, view_of_drone, views_from_states, views_of_drones
from rpf_fly.planning.wall_following import MODE_APF, MODE_NAMES, MODE_SOFT, MODE_WALL

__all__ = [
    "FAR",
    "MODE_APF",
    "MODE_NAMES",
    "MODE_SOFT",
    "MODE_WALL",
    "FixedGains",
    "GainsPolicy",
    "LocalView",
    "NearestObstacle",
    "Observation",
    "ObstacleSet",
    "PlanStep",
    "Planner",
    "PlannerConfig",
    "apf_step",
    "build_observation",
    "nearest_obstacle",
    "sense_obstacles",
    "view_of_drone",
    "views_from_states",
    "views_of_drones",
]
