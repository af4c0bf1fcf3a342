"""soft_snake_gym.agents: every way to get a policy, below training and the CLI."""

from __future__ import annotations

import subprocess
import sys

import pytest

from soft_snake_gym.agents import TrainedPolicy, make_policy, zoo_path
from soft_snake_gym.config import ConfigError
from soft_snake_gym.evaluation import make_eval_env
from soft_snake_gym.policies import CurvaturePID


def test_getting_a_policy_imports_neither_training_nor_the_cli():
    """The cycle cli -> policies -> training -> cli is gone: loading agents stays below them."""
    code = (
        "import sys, soft_snake_gym.agents, soft_snake_gym.evaluation; "
        "print(sorted(m for m in sys.modules if m.startswith(('soft_snake_gym.cli', "
        "'soft_snake_gym.training', 'soft_snake_gym.studies'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_one_spec_gives_a_baseline_a_shipped_agent_or_a_clear_error(tmp_path):
    env = make_eval_env("SoftEel-v0", seed=0)
    assert isinstance(make_policy("pid:Kd=2", env), CurvaturePID)
    agent = make_policy("zoo:ppo", env)
    assert isinstance(agent, TrainedPolicy) and agent.obs_rms is not None  # with its VecNormalize statistics
    assert (
        make_policy(str(zoo_path("SoftEel-v0", "ppo")), env).model.observation_space
        == agent.observation_space
    )
    with pytest.raises(ConfigError, match="no shipped sac agent for SoftEel-v0; shipped agents: zoo:ppo on"):
        make_policy("zoo:sac", env)
    with pytest.raises(ConfigError, match=r"run folder .* holds no model"):
        make_policy(str(tmp_path), env)
    with pytest.raises(ConfigError, match="unknown policy 'pdi'; did you mean 'pid'"):
        make_policy("pdi", env)
