"""The envs in RLlib (current API stack): env creators through Ray Tune's registry, one PPO iteration.

RLlib pins its own Gymnasium, so these run in the second venv the README's test block builds
(``.venv-rllib``), inside a loopback-only network namespace; without RLlib they skip.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from conftest import enter_loopback_namespace

from soft_snake_gym.config import ConfigError
from soft_snake_gym.distributed import worker_runtime_env
from soft_snake_gym.rllib import make_env, ppo_config, register


def test_the_creator_passes_env_config_as_the_envs_keywords():
    env = make_env("SoftEel-v0", {"max_episode_steps": 3, "energy_cost_weight": 0.5})
    assert env.unwrapped.settings.energy_cost_weight == 0.5
    env.reset(seed=0)
    truncated = [env.step(env.action_space.sample())[3] for _ in range(3)]
    assert truncated == [False, False, True]  # max_episode_steps reached the time limit


def test_register_puts_creators_in_rays_registry_and_rejects_unknown_ids():
    pytest.importorskip("ray.tune")
    from ray.tune.registry import ENV_CREATOR, _global_registry

    with pytest.raises(ConfigError, match="SoftEel-v0, SoftWorm-v0"):
        register(["SoftSnail-v0"])
    register()
    env = _global_registry.get(ENV_CREATOR, "SoftWorm-v0")({"max_episode_steps": 7})
    assert env.observation_space.shape == (39,)  # the worm's observation
    assert env.spec.max_episode_steps == 7


def _rllib_missing() -> str | None:
    """Why RLlib is not installed as the ``rllib`` extra installs it (``ray[rllib]``), or None.

    Ray's wheel always carries ``ray.rllib``; what the extra adds (its own Gymnasium among them)
    is what makes it the supported RLlib.
    """
    from importlib.metadata import PackageNotFoundError, requires, version

    from packaging.requirements import Requirement

    try:
        lines = requires("ray") or []
    except PackageNotFoundError:
        return "Ray is not installed"
    for line in lines:
        req = Requirement(line)
        if (
            req.marker is None
            or not req.marker.evaluate({"extra": "rllib"})
            or req.marker.evaluate({"extra": ""})
        ):
            continue
        try:
            have = version(req.name)
        except PackageNotFoundError:
            return f"ray[rllib] needs {req.name}{req.specifier}, which is not installed"
        if not req.specifier.contains(have, prereleases=True):
            return f"ray[rllib] needs {req.name}{req.specifier}, installed {have}"
    return None


RLLIB_MISSING = _rllib_missing()
if RLLIB_MISSING and os.environ.get("SOFT_SNAKE_REQUIRE_RLLIB"):
    # the README's RLlib venv sets this: there a missing RLlib is a failure, not a skip
    raise RuntimeError(
        f"SOFT_SNAKE_REQUIRE_RLLIB is set but RLlib is not installed as its extra: {RLLIB_MISSING}"
    )


@pytest.fixture()
def loopback_ray():
    """A local Ray on 127.0.0.1 (in this process's own network namespace), workers set up as the package's."""
    ray = pytest.importorskip("ray")
    enter_loopback_namespace()
    ray.init(
        address="local",  # a new Ray, even where `ray start` left a cluster's address behind
        num_cpus=2,
        include_dashboard=False,
        _node_ip_address="127.0.0.1",
        log_to_driver=False,
        runtime_env=worker_runtime_env(),
    )
    yield ray
    ray.shutdown()


@pytest.mark.slow
@pytest.mark.ray
@pytest.mark.skipif(RLLIB_MISSING is not None, reason=f"not RLlib's extra ({RLLIB_MISSING}): README, RLlib")
def test_one_ppo_iteration_on_softeel_samples_the_batch_on_a_remote_runner_and_learns(loopback_ray):
    pytest.importorskip("ray.rllib")
    import torch

    batch, episode = 200, 100
    config = ppo_config(
        "SoftEel-v0",
        {"max_episode_steps": episode},
        num_env_runners=1,  # the env is made in a Ray actor: the creator must reach it
        train_batch_size=batch,
        minibatch_size=100,
        num_epochs=1,
        lr=1e-3,
    )
    algo = config.build_algo()
    try:
        module = algo.get_module()
        assert module.observation_space.shape == (28,) and module.action_space.shape == (8,)  # the eel
        before = {k: v.detach().clone() for k, v in module.state_dict().items()}
        result = algo.train()
        after = algo.get_module().state_dict()
    finally:
        algo.stop()
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled"] == batch
    assert result["num_env_steps_sampled_lifetime"] == batch
    assert runners["num_episodes"] == batch // episode  # truncated by the time limit, no failure
    assert runners["episode_len_mean"] == episode
    ret = float(runners["episode_return_mean"])
    assert math.isfinite(ret) and abs(ret) < episode  # per step: speed [m/s] minus small costs
    changed = [k for k in before if not torch.equal(before[k], after[k])]
    assert changed, "the learner's weights did not change"
    assert all(np.isfinite(after[k].numpy()).all() for k in after)
