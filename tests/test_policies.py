"""The baseline controllers (docs/model.md §7) on the real envs, through SB3's evaluate_policy."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.agents import make_policy
from soft_snake_gym.config import ConfigError
from soft_snake_gym.evaluation import evaluate, make_eval_env
from soft_snake_gym.policies import (
    BASELINES,
    CurvaturePID,
    DecentralizedPhasePID,
    InchingPID,
    InchingWave,
    LOSGuidance,
    OpenLoopSerpenoid,
    PolicyEnvMismatch,
    parse_policy_spec,
)
from soft_snake_gym.studies.figures import rest_start_options, rollout

EEL = ["open-loop", "pid", "decentralized", "decentralized:closure=pacemaker"]
WORM = ["inching", "inching-pid"]


@pytest.mark.parametrize("spec", EEL + WORM)
def test_runs_through_sb3_evaluate_policy(spec):
    env_id = "SoftWorm-v0" if spec.startswith("inching") else "SoftEel-v0"
    venv = make_eval_env(env_id, n_envs=2, env_kwargs={"max_episode_steps": 60})
    policy = make_policy(spec, venv)
    rewards, lengths = evaluate_policy(policy, venv, n_eval_episodes=3, return_episode_rewards=True)
    assert lengths == [60, 60, 60]
    assert all(np.isfinite(rewards))


def test_state_is_the_clock_and_resets_on_episode_start():
    env = gym.make("SoftEel-v0")
    policy = CurvaturePID(env, Kp=0.1, Kd=0.0, Ki=1.0)  # small gains: no saturation
    obs, _ = env.reset(seed=0)
    batch = np.stack([obs, obs])
    a0, state = policy.predict(batch, None, np.array([True, True]))
    a1, state = policy.predict(batch, state, np.array([False, False]))
    assert np.allclose(state[:, 0], 2 * env.unwrapped.dt)  # the clock advanced twice
    assert not np.allclose(a0, a1)  # same observation, later time: another action
    a2, state2 = policy.predict(batch, state, np.array([True, False]))
    assert np.allclose(a2[0], a0[0]) and not np.allclose(a2[1], a0[1])
    assert state2[0, 0] == pytest.approx(env.unwrapped.dt)
    assert np.any(state[0, 1:] != 0)  # the integral had built up ...
    assert np.abs(state2[0, 1:]).max() < np.abs(state2[1, 1:]).max()  # ... and was reset for env 0


def test_open_loop_action_is_the_serpenoid_rate():
    env = gym.make("SoftEel-v0")
    obs, _ = env.reset(seed=0, options=rest_start_options())  # rest shape on the gait at t = 0
    policy = OpenLoopSerpenoid(env)
    alpha, omega, delta = math.pi / 6, 2 * math.pi / 3, math.pi / 4
    j = np.arange(1, 9)
    state = None
    for step in range(3):
        action, state = policy.predict(obs[None], state)
        psi = omega * step * env.unwrapped.dt + delta * j
        expected = alpha * omega * np.cos(psi) / np.cos(alpha * np.sin(psi) / 2) ** 2
        # later steps add rest_gain x the O(h^2) Euler drift of kbar (about 1e-4)
        tol = 1e-5 if step == 0 else 3e-3
        np.testing.assert_allclose(action[0] * env.unwrapped.max_curvature_rate, expected, atol=tol)
        obs, *_ = env.step(action[0])


def _mean_error(spec: str, seconds: float = 6.0, after: float = 2.0, **reset) -> float:
    tr = rollout("SoftEel-v0", spec, seconds, env_kwargs={"reset_noise_scale": 0.0}, **reset)
    return float(tr["error"][tr["t"][:-1] >= after].mean())


def test_pid_reduces_curvature_error_against_open_loop():
    venv = make_eval_env("SoftEel-v0")
    ol = evaluate(make_policy("open-loop", venv), venv, episodes=1)[0]
    pid = evaluate(make_policy("pid", venv), venv, episodes=1)[0]
    # measured: open loop 0.0227, PID 0.0070 (10 s from a straight body, after 2 s)
    assert pid["curvature_error"] < 0.5 * ol["curvature_error"]
    assert pid["average_speed"] > 0.05 and ol["average_speed"] > 0.05  # both swim toward the head


def test_decentralized_settles_within_twice_the_centralized_error():
    # the chain from the first step (no start-up on the clock), from the sources' start
    opts = {"reset_options": rest_start_options()}
    central = _mean_error("pid", **opts)
    central_same_gains = _mean_error("pid:Kd=2,Ki=1", **opts)
    circulant = _mean_error("decentralized:startup=0", **opts)
    pacemaker = _mean_error("decentralized:closure=pacemaker,startup=0", **opts)
    # measured: 0.0040, 0.0033, 0.0044, 0.0035
    for dec in (circulant, pacemaker):
        assert dec < 2 * central
        assert dec < 2 * central_same_gains
    # "slightly larger" than centralized, not smaller: the phase comes from a neighbour
    assert circulant > central_same_gains


def test_decentralized_start_up_runs_the_clock_then_the_chain():
    env = gym.make("SoftEel-v0")
    obs, _ = env.reset(seed=0)
    central = make_policy("pid:Kd=2,Ki=1", env)
    chain = make_policy("decentralized:startup=0.05", env)  # 5 control steps on the clock
    s_central = s_chain = None
    for step in range(8):
        a_central, s_central = central.predict(obs[None], s_central)
        a_chain, s_chain = chain.predict(obs[None], s_chain)
        # on the clock the same law on the same reference: bit for bit the centralized PID
        assert np.array_equal(a_chain, a_central) == (step < 5), step
        obs, *_ = env.step(a_central[0])


@pytest.mark.parametrize("seed", [9, 12])
def test_decentralized_start_up_starts_the_wave_where_the_bare_chain_stalls(seed):
    # measured at seed 9 / 12: 0.0000 / 0.0001 m/s without the start-up (every node bent one way,
    # the integral cancelling the feed-forward), 0.1247 m/s with it
    speeds = {}
    for spec in ("decentralized:startup=0", "decentralized"):
        venv = make_eval_env("SoftEel-v0", seed=seed)
        speeds[spec] = evaluate(make_policy(spec, venv), venv, episodes=1)[0]["average_speed"]
    assert abs(speeds["decentralized:startup=0"]) < 0.005
    assert speeds["decentralized"] > 0.12


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_decentralized_start_up_rejects_an_impossible_duration(value):
    env = gym.make("SoftEel-v0")
    with pytest.raises(ConfigError, match=r"startup = .* s must be finite and >= 0"):
        make_policy(f"decentralized:startup={value}", env)


@pytest.mark.parametrize("spec", WORM)
def test_inching_moves_the_worm_forward(spec):
    venv = make_eval_env("SoftWorm-v0", env_kwargs={"reset_noise_scale": 0.0})
    ep = evaluate(make_policy(spec, venv), venv, episodes=1)[0]
    inner = venv.envs[0].unwrapped
    assert ep["distance"] > 0.05  # toward the head (+x), measured 0.10 m in 10 s (0.105 closed loop)
    assert inner.sim.failure is None
    # reversing the wave reverses the motion
    back = evaluate(make_policy(spec + ":direction=-1", venv), venv, episodes=1)[0]
    assert back["distance"] < -0.05


def test_inching_pid_tracks_length_better_than_open_loop():
    venv = make_eval_env("SoftWorm-v0", env_kwargs={"reset_noise_scale": 0.0, "max_episode_steps": 300})
    ol = evaluate(make_policy("inching", venv), venv, episodes=1, transient=1.0)[0]
    cl = evaluate(make_policy("inching-pid", venv), venv, episodes=1, transient=1.0)[0]
    assert cl["length_error"] < ol["length_error"]


@pytest.mark.parametrize(
    ("spec", "env_id"), [("pid", "SoftWorm-v0"), ("decentralized", "SoftWorm-v0"), ("inching", "SoftEel-v0")]
)
def test_policy_for_the_wrong_env_is_rejected(spec, env_id):
    with pytest.raises(PolicyEnvMismatch, match="SoftWorm-v0|SoftEel-v0"):
        make_policy(spec, gym.make(env_id))


def test_spec_parsing_and_errors():
    assert parse_policy_spec("pid:alpha=pi/6,omega=2*pi/3,closure=pacemaker") == (
        "pid",
        {
            "alpha": pytest.approx(math.pi / 6),
            "omega": pytest.approx(2 * math.pi / 3),
            "closure": "pacemaker",
        },
    )
    env = gym.make("SoftEel-v0")
    p = make_policy("pid:alpha=0.5,omega=2.1,Kd=2", env)
    assert isinstance(p, CurvaturePID) and (p.params.alpha, p.params.omega, p.params.Kd) == (0.5, 2.1, 2.0)
    with pytest.raises(ConfigError, match="unknown policy 'pdi'.*'pid'"):
        make_policy("pdi", env)
    with pytest.raises(ConfigError, match="unknown key 'alpah'.*'alpha'"):
        make_policy("pid:alpah=0.5", env)
    with pytest.raises(ConfigError, match="Kp"):
        make_policy("pid:Kp=-1", env)
    with pytest.raises(ConfigError, match="does not exist"):
        make_policy("models/nope.zip", env)
    assert set(BASELINES.values()) == {
        OpenLoopSerpenoid,
        CurvaturePID,
        DecentralizedPhasePID,
        InchingWave,
        InchingPID,
        LOSGuidance,
    }


def test_gains_load_from_yaml(tmp_path):
    from pathlib import Path

    env = gym.make("SoftEel-v0")
    repo_cfg = Path(__file__).resolve().parents[1] / "soft_snake_gym" / "configs" / "policy" / "pid.yaml"
    p = CurvaturePID.from_yaml(env, repo_cfg)
    assert (p.params.Kp, p.params.Kd, p.params.Ki, p.params.saturation) == (10.0, 1.0, 5.0, 1.5)
    for name, cls, env_id in (
        ("pid_soft.yaml", CurvaturePID, "SoftEel-v0"),
        ("decentralized.yaml", DecentralizedPhasePID, "SoftEel-v0"),
        ("open_loop.yaml", OpenLoopSerpenoid, "SoftEel-v0"),
        ("inching.yaml", InchingPID, "SoftWorm-v0"),
    ):
        policy = cls.from_yaml(gym.make(env_id), repo_cfg.parent / name)
        assert isinstance(policy, cls)
    assert make_policy("decentralized", env, config=repo_cfg.parent / "decentralized.yaml").params.Kd == 2.0
    bad = tmp_path / "bad.yaml"
    bad.write_text("Kp: 10\nKdd: 1\n")
    with pytest.raises(ConfigError, match="'Kdd'.*'Kd'"):
        CurvaturePID.from_yaml(env, bad)
