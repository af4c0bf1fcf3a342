"""Registration of the environment ids with Gymnasium (done on ``import soft_snake_gym``).

Gymnasium 1.x has no plugin entry points: ``gym.make("soft_snake_gym:SoftEel-v0")`` imports
``soft_snake_gym``, whose import calls :func:`register_envs`. Calling it again is harmless.

Each id also has a ``vector_entry_point``, the batched :class:`~soft_snake_gym.envs.vector.SoftVectorEnv`:
Gymnasium 1.x's ``gym.make_vec(id, num_envs=...)`` uses it unless ``vectorization_mode`` says
``"sync"`` or ``"async"``.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = [
    "ENV_IDS",
    "EPISODE_STEPS",
    "VECTOR_ENTRY_POINTS",
    "MAX_EPISODE_STEPS",
    "importable_id",
    "register_envs",
]

MAX_EPISODE_STEPS = 1000
ENV_IDS = {
    "SoftEel-v0": "soft_snake_gym.envs.swim:SwimEnv",
    "SoftWorm-v0": "soft_snake_gym.envs.inch:InchEnv",
    "SoftEelGoal-v0": "soft_snake_gym.envs.navigate:GoalEnv",
    "SoftEelPath-v0": "soft_snake_gym.envs.navigate:PathEnv",
    "SoftEelSegments-v0": "soft_snake_gym.multiagent.segments:SegmentsEnv",
}
VECTOR_ENTRY_POINTS = {
    "SoftEel-v0": "soft_snake_gym.envs.vector:SwimVectorEnv",
    "SoftWorm-v0": "soft_snake_gym.envs.vector:InchVectorEnv",
    "SoftEelGoal-v0": "soft_snake_gym.envs.vector:GoalVectorEnv",
    "SoftEelPath-v0": "soft_snake_gym.envs.vector:PathVectorEnv",
}
EPISODE_STEPS = {
    "SoftEel-v0": MAX_EPISODE_STEPS,
    "SoftWorm-v0": MAX_EPISODE_STEPS,
    "SoftEelGoal-v0": 3000,
    "SoftEelPath-v0": 3000,
    "SoftEelSegments-v0": MAX_EPISODE_STEPS,
}
"""Steps per episode of each id (``TimeLimit``): 10 s, or 30 s to steer to a target or onto a path."""


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` unless already registered.

    :data:`EPISODE_STEPS` steps each, with their batched vector entry points.
    """
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point=entry_point,
                max_episode_steps=EPISODE_STEPS[env_id],
                vector_entry_point=VECTOR_ENTRY_POINTS.get(env_id),
            )


def importable_id(env_id: str) -> str:
    """``env_id`` as a fresh process can make it: ``"soft_snake_gym:SoftEel-v0"``.

    ``gym.make`` imports the module before the ``:``, which registers the ids. Worker processes
    (SB3's ``SubprocVecEnv``) need it: started by ``python -m soft_snake_gym.cli``, they do not
    import the package, since multiprocessing does not re-run a main module named ``__main__``.
    """
    return env_id if ":" in env_id else f"soft_snake_gym:{env_id}"
