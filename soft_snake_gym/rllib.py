"""The envs for RLlib: env creators registered with Ray Tune's registry.

Gymnasium's registry lives in one process and does not reach Ray's workers; RLlib finds an env
by a name registered with ``ray.tune.registry.register_env``, whose creator Ray pickles to every
worker. :func:`register` registers ``SoftEel-v0`` and ``SoftWorm-v0`` under their Gymnasium ids,
each a creator that takes RLlib's ``env_config`` as the env's keywords::

    import soft_snake_gym.rllib
    from ray.rllib.algorithms.ppo import PPOConfig

    soft_snake_gym.rllib.register()
    config = PPOConfig().environment("SoftEel-v0", env_config={"energy_cost_weight": 0.011})

RLlib (``pip install -e ".[rllib]"``, ``ray[rllib]==2.60.0``) pins Gymnasium 1.2.2, which the
package's range admits: install it in a venv of its own (README, RLlib).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from typing import Any

import gymnasium as gym

from soft_snake_gym.config import ConfigError
from soft_snake_gym.envs import register_envs
from soft_snake_gym.envs.registration import ENV_IDS

__all__ = ["INSTALL", "make_env", "ppo_config", "register"]

#: What to run when Ray is missing.
INSTALL = 'pip install torch==2.13.0 && pip install -e ".[rllib]" (in a venv of its own: see the README)'


def make_env(env_id: str, env_config: dict[str, Any] | None = None) -> gym.Env:
    """One env as RLlib's workers make it: ``gym.make(env_id, **env_config)``.

    Args:
        env_id: ``SoftEel-v0`` or ``SoftWorm-v0``.
        env_config: the env's keywords (RLlib passes an ``EnvContext``, a dict that also knows
            the worker's index; only its keys are used). ``max_episode_steps`` sets the time
            limit as in ``gym.make``.
    """
    register_envs()  # a worker that unpickled this function has imported the package; be sure
    return gym.make(env_id, **dict(env_config or {}))


def register(env_ids: Iterable[str] = tuple(ENV_IDS)) -> None:
    """Register an RLlib env creator under each Gymnasium id (in Ray Tune's registry).

    Call it in the driver before building an algorithm; the creators reach the workers by
    pickle. Repeating it is harmless.

    Raises:
        ConfigError: an id this package does not have.
        ImportError: Ray is not installed (the message says what to install).
    """
    env_ids = list(env_ids)
    for env_id in env_ids:
        if env_id not in ENV_IDS:
            raise ConfigError(f"env id {env_id!r} is not one of this package's: {', '.join(ENV_IDS)}")
    try:
        from ray.tune.registry import register_env  # here, not above: Ray is an optional extra
    except ImportError:
        raise ImportError(f"RLlib's env registry needs Ray: {INSTALL}") from None
    for env_id in env_ids:
        creator: Callable[[dict[str, Any]], gym.Env] = functools.partial(make_env, env_id)
        register_env(env_id, creator)


def ppo_config(
    env_id: str = "SoftEel-v0",
    env_config: dict[str, Any] | None = None,
    num_env_runners: int = 0,
    train_batch_size: int = 4000,
    minibatch_size: int = 128,
    num_epochs: int = 10,
    lr: float = 3e-4,
    gamma: float = 0.99,
    seed: int = 0,
):
    """RLlib's PPO (current API stack) on one of the envs, with its creator registered.

    Actions are clipped to the env's bounds before the env sees them, as SB3 does.

    Args:
        env_id: ``SoftEel-v0`` or ``SoftWorm-v0``.
        env_config: the env's keywords (``max_episode_steps`` included).
        num_env_runners: remote sampling actors (0: sample in the driver's local runner).
        train_batch_size: environment steps sampled per training iteration (per learner).
        minibatch_size: steps per SGD minibatch.
        num_epochs: passes over each batch.
        lr: the learning rate.
        gamma: the discount factor.
        seed: seeds the env runners (envs and sampling) and the learner.

    Returns:
        ``ray.rllib.algorithms.ppo.PPOConfig``; ``.build_algo()`` makes the algorithm.

    Raises:
        ConfigError: an unknown env id or a batch smaller than a minibatch.
        ImportError: RLlib is not installed (the message says what to install).
    """
    if minibatch_size > train_batch_size:
        raise ConfigError(
            f"minibatch_size = {minibatch_size} must be at most train_batch_size = {train_batch_size}"
        )
    register([env_id])
    try:
        from ray.rllib.algorithms.ppo import PPOConfig  # here, not above: optional, seconds to import
    except ImportError:
        raise ImportError(f"RLlib is not installed: {INSTALL}") from None
    return (
        PPOConfig()
        # actions clipped to the env's Box before the env sees them, as SB3 does (the control cost
        # would otherwise charge the Gaussian's samples beyond +-1, which the env clips anyway)
        .environment(env_id, env_config=dict(env_config or {}), clip_actions=True)
        # RLlib's 60 s default gives up on a runner still making its envs (numba's cache, imports)
        .env_runners(num_env_runners=num_env_runners, sample_timeout_s=600.0)
        .training(
            train_batch_size_per_learner=train_batch_size,
            minibatch_size=minibatch_size,
            num_epochs=num_epochs,
            lr=lr,
            gamma=gamma,
        )
        .debugging(seed=seed)
    )
