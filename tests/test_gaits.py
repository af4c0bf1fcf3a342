"""The peristaltic pulse wave (docs/model.md §6) and its use in the inching baselines."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.agents import make_policy
from soft_snake_gym.config import ConfigError
from soft_snake_gym.evaluation import evaluate, make_eval_env
from soft_snake_gym.gaits import length_wave, pulse_wave
from soft_snake_gym.policies import InchingPID, InchingWave
from soft_snake_gym.policies.inching import PULSE_DUTY

L0, EPS, OMEGA, N_EDGES = 0.18, 0.3, 2 * math.pi, 9
DELTA = 2 * math.pi / N_EDGES


@pytest.mark.parametrize("duty", [0.2, 0.3, 0.5, 0.6, 0.8])
def test_pulse_compresses_only_a_duty_fraction_of_the_edges_the_rest_at_rest_length(duty):
    counts = []
    for t in np.linspace(0.0, 3.0, 3001):  # three periods
        lbar, _ = pulse_wave(t, N_EDGES, L0, EPS, OMEGA, DELTA, duty)
        inside = lbar < L0
        assert np.all(lbar[~inside] == L0)  # anchored edges sit exactly at rest length
        assert lbar.min() >= L0 * (1 - EPS) - 1e-15
        k = np.flatnonzero(inside)
        if k.size:  # one contiguous pulse (cyclically)
            gaps = np.diff(np.concatenate([k, [k[0] + N_EDGES]]))
            assert np.count_nonzero(gaps > 1) <= 1
        counts.append(k.size)
        assert k.size <= math.ceil(duty * N_EDGES)
    # each edge is in the pulse a fraction duty of the time: duty (N - 1) edges on average
    assert np.mean(counts) == pytest.approx(duty * N_EDGES, abs=0.02)


@pytest.mark.parametrize(("duty", "direction"), [(0.3, 1), (0.6, 1), (1.0, 1), (0.4, -1)])
def test_pulse_rate_is_the_time_derivative_of_the_rest_length(duty, direction):
    dt = 1e-6
    rng = np.random.default_rng(0)
    peak = 0.5 * L0 * EPS * OMEGA / duty
    for t in rng.uniform(0.0, 2.0, 200):
        lo, _ = pulse_wave(t - dt, N_EDGES, L0, EPS, OMEGA, DELTA, duty, direction)
        hi, _ = pulse_wave(t + dt, N_EDGES, L0, EPS, OMEGA, DELTA, duty, direction)
        _, rate = pulse_wave(t, N_EDGES, L0, EPS, OMEGA, DELTA, duty, direction)
        assert np.allclose((hi - lo) / (2 * dt), rate, rtol=0, atol=1e-6 * peak)
        assert np.abs(rate).max() <= peak * (1 + 1e-12)  # bounded, as documented


def test_pulse_travels_tail_to_head_and_duty_one_is_the_sine_wave_later():
    def centre(t, direction):  # most compressed edge
        return int(np.argmin(pulse_wave(t, N_EDGES, L0, EPS, OMEGA, DELTA, 0.3, direction)[0]))

    steps = [centre(t, 1) for t in np.arange(0.0, 0.99, 1 / N_EDGES)]
    assert np.all(np.diff(steps) % N_EDGES == 1)  # one edge toward the head per 1/9 period
    steps = [centre(t, -1) for t in np.arange(0.0, 0.99, 1 / N_EDGES)]
    assert np.all(np.diff(steps) % N_EDGES == N_EDGES - 1)
    quarter = math.pi / (2 * OMEGA)
    for t in (0.0, 0.13, 0.71):
        pulse = pulse_wave(t, N_EDGES, L0, EPS, OMEGA, DELTA, 1.0)
        sine = length_wave(t - quarter, N_EDGES, L0, EPS, OMEGA, DELTA)
        assert np.allclose(pulse[0], sine[0]) and np.allclose(pulse[1], sine[1])


def test_bad_pulse_values_are_rejected():
    for duty in (0.0, -0.1, 1.5, math.nan):
        with pytest.raises(ValueError, match=r"duty = .* must be in \(0, 1\]"):
            pulse_wave(0.0, N_EDGES, L0, EPS, OMEGA, DELTA, duty)
    with pytest.raises(ValueError, match="direction"):
        pulse_wave(0.0, N_EDGES, L0, EPS, OMEGA, DELTA, 0.5, direction=0)
    env = gym.make("SoftWorm-v0")
    with pytest.raises(ConfigError, match=r"wave = 'square' must be one of \['sine', 'pulse'\]"):
        make_policy("inching:wave=square", env)
    with pytest.raises(ConfigError, match=r"duty = 0(\.0)? must be in \(0, 1\]"):
        make_policy("inching-pid:wave=pulse,duty=0", env)
    with pytest.raises(ConfigError, match=r"duty = 1.2 must be in \(0, 1\]"):
        make_policy("inching:wave=pulse,duty=1.2", env)
    with pytest.raises(ConfigError, match="duty = 0.5 applies to wave='pulse' only"):
        make_policy("inching:wave=sine,duty=0.5", env)
    with pytest.raises(ValueError, match="wave = 'square'"):
        InchingWave(env, wave="square")


def test_pulse_spec_builds_the_policy_and_its_desired_lengths_are_the_pulse():
    env = gym.make("SoftWorm-v0")
    p = make_policy("inching-pid:wave=pulse,duty=0.7", env)
    assert isinstance(p, InchingPID) and (p.params.wave, p.params.duty) == ("pulse", 0.7)
    t = np.array([0.0, 0.37])
    lbar, rate = p.desired(t)
    for i, ti in enumerate(t):
        expect = pulse_wave(ti, N_EDGES, L0, EPS, OMEGA, DELTA, 0.7)
        assert np.array_equal(lbar[i], expect[0]) and np.array_equal(rate[i], expect[1])
    default = make_policy("inching:wave=pulse", env)
    assert default.duty == PULSE_DUTY
    assert make_policy("inching", env).params.wave == "pulse"  # it moves the worm furthest


def test_a_pulse_faster_than_the_actuators_warns():
    env = gym.make("SoftWorm-v0")  # max_length_rate 0.3 m/s; the pulse peaks at 0.17 m/s / duty
    with pytest.warns(UserWarning, match="exceeds the env's max_length_rate"):
        make_policy("inching:wave=pulse,duty=0.3", env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_policy("inching:wave=pulse", env)  # the default duty fits
        make_policy("inching", env)


def test_the_worm_holds_the_edges_outside_the_pulse_at_rest_length():
    """Physics of the gait.

    Under the open-loop pulse the rest lengths outside the pulse stay at l0, so at most about duty
    (N - 1) edges change at a time, and the worm moves forward.
    """
    duty = 0.6  # its peak rate fits the actuators (0.28 of 0.3 m/s), so nothing is clipped
    # the gait's own shape, without the actuators' lag: through the default 0.05 s lag each edge
    # returns to l0 on an exponential tail, and 6.2 edges are off l0 on average instead of 5.4
    kwargs = {"reset_noise_scale": 0.0, "max_episode_steps": 300, "rod": {"length_lag": 0.0}}
    venv = make_eval_env("SoftWorm-v0", env_kwargs=kwargs)
    policy = make_policy(f"inching:wave=pulse,duty={duty}", venv)
    changed = []

    def record(locals_, globals_):
        lbar = venv.envs[0].unwrapped.sim.lbar
        changed.append(np.count_nonzero(lbar < L0 * (1 - 1e-3 * EPS)))

    from stable_baselines3.common.evaluation import evaluate_policy

    evaluate_policy(policy, venv, n_eval_episodes=1, callback=record)
    steady = np.array(changed[100:])  # after the first second
    assert steady.max() <= math.ceil(duty * N_EDGES) + 1
    assert steady.mean() == pytest.approx(duty * N_EDGES, abs=0.6)
    ep = evaluate(policy, venv, episodes=1)[0]
    assert ep["distance"] > 0.05 and ep["failure"] == ""


def test_evaluate_knows_the_pulse_rate_grows_with_one_over_duty():
    from soft_snake_gym.evaluation import gait_rate_warning

    env = gym.make("SoftWorm-v0")  # max_length_rate 0.3 m/s; the pulse peaks at 0.17 m/s / duty
    assert gait_rate_warning(make_policy("inching:wave=pulse,duty=0.6", env), env) is None
    with pytest.warns(UserWarning):  # the policy's own warning at construction
        fast = make_policy("inching:wave=pulse,duty=0.3", env)
    assert "0.565 m/s, beyond the env's max_length_rate" in gait_rate_warning(fast, env)
