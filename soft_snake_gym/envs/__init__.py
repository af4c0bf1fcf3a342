"""Gymnasium environments: the eel, the worm, and the eel's navigation tasks.

``SoftEel-v0`` (:class:`SwimEnv`), ``SoftWorm-v0`` (:class:`InchEnv`), ``SoftEelGoal-v0``
(:class:`GoalEnv`) and ``SoftEelPath-v0`` (:class:`PathEnv`). The batched :class:`SoftVectorEnv` steps many robots in one compiled call (``gym.make_vec``).
Importing ``soft_snake_gym`` registers the ids, so ``gym.make("SoftEel-v0")`` works after
``import soft_snake_gym`` and ``gym.make("soft_snake_gym:SoftEel-v0")`` works without it.
"""

from soft_snake_gym.envs.base import SoftRobotEnv
from soft_snake_gym.envs.inch import InchEnv, InchSettings
from soft_snake_gym.envs.navigate import GoalEnv, GoalSettings, PathEnv, PathSettings
from soft_snake_gym.envs.registration import ENV_IDS, register_envs
from soft_snake_gym.envs.settings import Randomization
from soft_snake_gym.envs.swim import SwimEnv, SwimSettings
from soft_snake_gym.envs.task import TaskArrays
from soft_snake_gym.envs.vector import (
    GoalVectorEnv,
    InchVectorEnv,
    PathVectorEnv,
    RobotBatch,
    SoftVectorEnv,
    SwimVectorEnv,
)

__all__ = [
    "ENV_IDS",
    "GoalEnv",
    "GoalSettings",
    "GoalVectorEnv",
    "PathEnv",
    "PathSettings",
    "PathVectorEnv",
    "InchEnv",
    "InchSettings",
    "InchVectorEnv",
    "Randomization",
    "RobotBatch",
    "SoftRobotEnv",
    "SoftVectorEnv",
    "SwimEnv",
    "SwimSettings",
    "SwimVectorEnv",
    "TaskArrays",
    "register_envs",
]
