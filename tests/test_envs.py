"""SoftEel-v0 and SoftWorm-v0: the Gymnasium contract, determinism, rewards, physics, config."""

from __future__ import annotations

import dataclasses
import math
import pickle
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import soft_snake_gym
from soft_snake_gym import Simulator, body_from_curvature
from soft_snake_gym.config import ConfigError
from soft_snake_gym.envs import InchEnv, InchSettings, SwimEnv, SwimSettings
from soft_snake_gym.gaits import pulse_wave, serpenoid, serpenoid_phase
from soft_snake_gym.physics import layout as L

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "soft_snake_gym" / "configs" / "env"
IDS = ["SoftEel-v0", "SoftWorm-v0"]
NAV_IDS = ["SoftEelGoal-v0", "SoftEelPath-v0"]  # the navigation tasks (tests/test_navigation.py)
G = 9.81


def assert_same(a, b, path="info"):
    """Exact equality of nested dicts / arrays / scalars (no tolerance)."""
    assert type(a) is type(b), f"{path}: {type(a)} vs {type(b)}"
    if isinstance(a, dict):
        assert a.keys() == b.keys(), f"{path}: keys {a.keys()} vs {b.keys()}"
        for k in a:
            assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert np.array_equal(a, b), f"{path}: {a} vs {b}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def rollout(env, seed, n, action_seed=1):
    rng = np.random.default_rng(action_seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, False, False, info)]
    for _ in range(n):
        a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, trunc, info))
        if term or trunc:
            obs, info = env.reset()
            out.append((obs, 0.0, False, False, info))
    return out


# --- registration and the Gymnasium contract -------------------------------------------------
def test_ids_registered_with_time_limit_and_repeatable_registration():
    soft_snake_gym.envs.register_envs()  # a second registration must be harmless
    for env_id in IDS:
        assert gym.spec(env_id).max_episode_steps == 1000
    for env_id in NAV_IDS:  # 30 s to turn and reach a target or a path
        assert gym.spec(env_id).max_episode_steps == 3000
    env = gym.make("SoftEel-v0")
    assert isinstance(env.unwrapped, SwimEnv)
    assert isinstance(env.unwrapped.sim, Simulator)
    assert env.unwrapped.dt == 0.01
    assert isinstance(gym.make("SoftWorm-v0").unwrapped, InchEnv)


def test_make_with_module_prefix_imports_the_package():
    code = (
        "import sys, gymnasium as gym\n"
        "assert 'soft_snake_gym' not in sys.modules\n"
        "env = gym.make('soft_snake_gym:SoftEel-v0')\n"
        "obs, _ = env.reset(seed=0)\n"
        "print(type(env.unwrapped).__name__, obs.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "SwimEnv (28,)"


@pytest.mark.parametrize("env_id", IDS + NAV_IDS)
def test_gymnasium_check_env_without_warnings(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)  # includes the rgb_array render check through env.spec


@pytest.mark.parametrize("env_id", IDS + NAV_IDS)
def test_sb3_check_env_without_warnings(env_id):
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(env_id).unwrapped, warn=True)


@pytest.mark.parametrize("env_id", IDS)
def test_spaces_are_float32_boxes_with_named_finite_layout(env_id):
    env = gym.make(env_id).unwrapped
    assert env.action_space.dtype == np.float32
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    box = env.observation_space
    assert box.dtype == np.float32 and np.all(np.isfinite(box.low)) and np.all(np.isfinite(box.high))
    assert sum(env.observation_structure.values()) == box.shape[0]
    N = env.N
    if env_id == "SoftEel-v0":
        assert list(env.observation_structure.items()) == [
            ("kappa", N - 2),
            ("kappa_dot", N - 2),
            ("kbar", N - 2),
            ("com_velocity_body", 2),
            ("goal_direction_body", 2),
        ]
        assert env.action_space.shape == (N - 2,)
        assert env.max_curvature_rate == 2 * math.pi
    else:
        assert list(env.observation_structure.items()) == [
            ("edge_lengths", N - 1),
            ("edge_length_rates", N - 1),
            ("lbar", N - 1),
            ("stuck", N),
            ("com_velocity_body", 2),
        ]
        assert env.action_space.shape == (N - 1,)
        # covers the inching wave of docs/model.md §6 at eps = 0.3, omega = 2 pi
        assert env.max_length_rate >= 0.5 * 0.18 * 0.3 * 2 * math.pi


def test_observation_blocks_hold_the_simulator_quantities():
    env = gym.make("SoftEel-v0", initial_shape="serpenoid")
    obs, _ = env.reset(seed=3)
    for _ in range(20):
        obs, *_ = env.step(env.action_space.sample())
    sim, s = env.unwrapped.sim, env.unwrapped.observation_structure
    parts = dict(zip(s, np.split(obs, np.cumsum(list(s.values()))[:-1]), strict=True))
    np.testing.assert_allclose(parts["kappa"], sim.kappa, rtol=1e-6)
    np.testing.assert_allclose(parts["kappa_dot"], sim.kappa_dot, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(parts["kbar"], sim.kbar, rtol=1e-6)
    h = sim.heading
    v = sim.com_velocity
    np.testing.assert_allclose(
        parts["com_velocity_body"],
        [v @ [math.cos(h), math.sin(h)], v @ [-math.sin(h), math.cos(h)]],
        rtol=1e-5,
        atol=1e-7,
    )
    np.testing.assert_allclose(parts["goal_direction_body"], [math.cos(-h), math.sin(-h)], rtol=1e-6)

    worm = gym.make("SoftWorm-v0")
    obs, _ = worm.reset(seed=3)
    for _ in range(20):
        obs, *_ = worm.step(worm.action_space.sample())
    sim, s = worm.unwrapped.sim, worm.unwrapped.observation_structure
    parts = dict(zip(s, np.split(obs, np.cumsum(list(s.values()))[:-1]), strict=True))
    np.testing.assert_allclose(parts["edge_lengths"], sim.edge_lengths, rtol=1e-6)
    np.testing.assert_allclose(parts["edge_length_rates"], sim.edge_length_rates, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(parts["lbar"], sim.lbar, rtol=1e-6)
    np.testing.assert_array_equal(parts["stuck"], sim.stuck.astype(np.float32))


# --- determinism and pickling ------------------------------------------------------------------
@pytest.mark.parametrize("env_id", IDS + NAV_IDS)
@pytest.mark.parametrize("randomize", [False, True])
def test_exact_determinism_of_a_200_step_random_rollout(env_id, randomize):
    medium = {"rho": [900.0, 1100.0]} if env_id != "SoftWorm-v0" else {"mu_s": [0.9, 1.2]}
    kwargs = {"randomize": {"E": [1.5e6, 2.5e6], **medium}} if randomize else {}
    a = rollout(gym.make(env_id, **kwargs), seed=7, n=200)
    b = rollout(gym.make(env_id, **kwargs), seed=7, n=200)
    assert len(a) == len(b)
    for i, (ra, rb) in enumerate(zip(a, b, strict=True)):
        assert_same(ra, rb, f"step {i}")
    c = rollout(gym.make(env_id, **kwargs), seed=8, n=5)
    assert not np.array_equal(a[0][0], c[0][0]), "a different seed must give a different start"


@pytest.mark.parametrize("env_id", IDS + NAV_IDS)
def test_pickle_round_trip_continues_identically(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=11)
    rng = np.random.default_rng(0)
    for _ in range(30):
        env.step(rng.uniform(-0.5, 0.5, env.action_space.shape).astype(np.float32))
    env.render()  # a live matplotlib figure must not break pickling
    clone = pickle.loads(pickle.dumps(env))
    np.testing.assert_array_equal(clone.unwrapped.sim.x, env.unwrapped.sim.x)
    for _ in range(30):
        act = rng.uniform(-0.5, 0.5, env.action_space.shape).astype(np.float32)
        assert_same(env.step(act), clone.step(act))
    assert_same(env.reset(), clone.reset())  # the np_random stream was carried over too
    assert clone.render().shape == env.render().shape


# --- rewards, metrics and physics ------------------------------------------------------------
@pytest.mark.parametrize("env_id", IDS)
def test_reward_is_the_sum_of_its_terms_in_info(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    seen = set()
    for _ in range(50):
        _, reward, term, _, info = env.step(env.action_space.sample())
        terms = {k: v for k, v in info.items() if k.startswith("reward_")}
        assert set(terms) == {"reward_forward", "reward_energy", "reward_ctrl", "reward_failure"}
        assert reward == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-15)
        seen |= {k for k, v in terms.items() if v != 0.0}
        assert not term
    assert {"reward_forward", "reward_energy", "reward_ctrl"} <= seen


def test_reward_terms_follow_their_weights():
    kw = {"forward_reward_weight": 2.0, "energy_cost_weight": 0.5, "ctrl_cost_weight": 0.25}
    env = gym.make("SoftEel-v0", **kw)
    env.reset(seed=0)
    action = np.full(8, 0.5, dtype=np.float32)
    _, _, _, _, info = env.step(action)
    assert info["reward_forward"] == pytest.approx(2.0 * info["forward_speed"])
    assert info["reward_energy"] == pytest.approx(-0.5 * abs(info["actuator_power"]))
    assert info["reward_ctrl"] == pytest.approx(-0.25 * 8 * 0.25)
    assert info["reward_energy"] < 0


def test_zero_action_leaves_a_straight_eel_still():
    env = gym.make("SoftEel-v0", reset_noise_scale=0.0)
    _, info = env.reset(seed=0)
    x0 = env.unwrapped.sim.x
    np.testing.assert_allclose(x0[:, 1], 0.0, atol=1e-15)  # straight along +x
    assert np.all(np.diff(x0[:, 0]) > 0)
    zero = np.zeros(8, dtype=np.float32)
    for _ in range(200):
        obs, reward, term, trunc, info = env.step(zero)
    assert not term
    assert np.abs(env.unwrapped.sim.x - x0).max() < 1e-12
    assert np.abs(env.unwrapped.sim.v).max() < 1e-12
    assert abs(reward) < 1e-12 and abs(info["forward_speed"]) < 1e-10
    assert info["fluid_power"] == 0.0 and info["actuator_power"] == 0.0
    assert np.abs(obs).max() == pytest.approx(1.0)  # only cos(goal - heading) = 1 is nonzero


def _serpenoid_rollout(env, alpha, omega, steps):
    """Open-loop serpenoid through the env's normalized actions (docs/model.md §7)."""
    u = env.unwrapped
    n = u.N - 2
    delta = 2 * math.pi / n
    for _ in range(steps):
        t = u.sim.time
        _, kd = serpenoid(serpenoid_phase(t + 0.5 * u.dt, n, omega, delta), omega, alpha)
        out = env.step((kd / u.max_curvature_rate).astype(np.float32))
        if out[2] or out[3]:
            return out
    return out


def test_serpenoid_gait_swims_forward_and_metrics_add_up_at_truncation():
    alpha, omega = math.pi / 4, math.pi
    env = gym.make("SoftEel-v0", initial_shape="serpenoid", serpenoid_alpha=alpha, reset_noise_scale=0.0)
    env.reset(seed=0)
    kbar0 = env.unwrapped.sim.kbar
    np.testing.assert_allclose(kbar0, serpenoid(serpenoid_phase(0, 8, omega, math.pi / 4), 0, alpha)[0])
    np.testing.assert_allclose(env.unwrapped.sim.kappa, kbar0, atol=1e-12)
    _, _, term, trunc, info = _serpenoid_rollout(env, alpha, omega, 1000)
    assert trunc and not term and info["failure"] is None
    m = info["metrics"]
    sim = env.unwrapped.sim
    assert m["duration"] == pytest.approx(10.0)
    assert m["distance"] > 1.0  # about 0.2 m/s along +x
    assert m["average_speed"] == pytest.approx(m["distance"] / m["duration"])
    assert m["distance"] == pytest.approx(info["x_position"] - 0.0, abs=1e-9)
    assert m["energy_actuator"] == pytest.approx(sim.actuator_energy)
    assert m["energy_fluid"] == pytest.approx(sim.fluid_energy) and m["energy_fluid"] > 0
    assert m["cost_of_transport"] == pytest.approx(m["energy_actuator"] / (7.2 * G * m["distance"]))


def test_inching_wave_moves_the_worm_forward_and_reports_friction():
    env = gym.make("SoftWorm-v0", reset_noise_scale=0.0)
    env.reset(seed=0)
    u = env.unwrapped
    total_friction = 0.0
    for _ in range(300):  # the peristaltic pulse (the sine wave anchors too little to move it)
        _, ld = pulse_wave(u.sim.time, u.N - 1, 0.18, 0.3, 2 * math.pi, math.pi / 4, 0.6)
        _, reward, term, _, info = env.step((ld / u.max_length_rate).astype(np.float32))
        assert not term
        total_friction += info["friction_power"] * u.dt
        assert info["reward_energy"] == pytest.approx(-1e-3 * info["friction_power"])
    m = info["metrics"]
    assert m["distance"] > 0.01
    assert m["energy_friction"] == pytest.approx(total_friction) and m["energy_friction"] > 0
    assert m["cost_of_transport"] == pytest.approx(m["energy_actuator"] / (7.2 * G * m["distance"]))
    assert info["stuck"].dtype == bool and info["stuck"].shape == (10,)


def test_cost_of_transport_takes_gravity_from_the_ground():
    env = gym.make("SoftWorm-v0", reset_noise_scale=0.0, ground={"g": 4.0})
    env.reset(seed=0)
    u = env.unwrapped
    for _ in range(100):
        _, ld = pulse_wave(u.sim.time, u.N - 1, 0.18, 0.3, 2 * math.pi, math.pi / 4, 0.6)
        info = env.step((ld / u.max_length_rate).astype(np.float32))[4]
    m = info["metrics"]
    assert m["distance"] > 0
    assert m["cost_of_transport"] == pytest.approx(m["energy_actuator"] / (7.2 * 4.0 * m["distance"]))


def test_actuator_energy_source_for_the_worm():
    env = gym.make("SoftWorm-v0", energy_source="actuator")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full(9, -0.5, dtype=np.float32))
    assert info["reward_energy"] == pytest.approx(-1e-3 * abs(info["actuator_power"]))
    assert info["actuator_power"] != 0.0


def test_rest_lengths_stop_at_their_bounds():
    # through the actuators' lag (0.05 s): the rate is cut early enough that the coasting rest
    # length lands on the bound, never past it (cutting at the bound itself overshoots 1.5 %)
    env = gym.make("SoftWorm-v0")
    env.reset(seed=0)
    for sign, bound in ((1, 1.5 * 0.18), (-1, 0.5 * 0.18)):
        for _ in range(200):  # 0.3 m/s reaches either bound from the other within 0.6 s
            obs, _, term, _, info = env.step(np.full(9, sign, dtype=np.float32))
            assert not term, info["failure"]
            lbar = env.unwrapped.sim.lbar
            assert np.all(lbar <= 1.5 * 0.18 + 1e-12) and np.all(lbar >= 0.5 * 0.18 - 1e-12)
        np.testing.assert_allclose(env.unwrapped.sim.lbar, bound, rtol=1e-12)
        np.testing.assert_allclose(info["edge_lengths"], bound, rtol=2e-2)  # the body follows


def test_rest_curvature_stops_at_its_bound():
    env = gym.make("SoftEel-v0")
    kbar = np.zeros(8)
    kbar[3] = 3.99
    env.reset(seed=0, options={"kbar": kbar})
    env.step(np.ones(8, dtype=np.float32))
    got = env.unwrapped.sim.kbar
    assert got[3] == pytest.approx(4.0, abs=1e-12)
    np.testing.assert_allclose(np.delete(got, 3), 0.01 * 2 * math.pi, rtol=1e-12)
    env.step(np.ones(8, dtype=np.float32))
    assert env.unwrapped.sim.kbar[3] == pytest.approx(4.0, abs=1e-12)


def test_out_of_range_actions_are_clipped_not_scaled():
    a, b = gym.make("SoftEel-v0"), gym.make("SoftEel-v0")
    a.reset(seed=5)
    b.reset(seed=5)
    big = np.array([5, -3, 1, 0, 0, 2, -1, 0], dtype=np.float32)
    assert_same(a.step(big), b.step(np.clip(big, -1, 1)))


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.full(8, np.nan, dtype=np.float32), "non-finite"),
        (np.zeros(7, dtype=np.float32), r"shape \(7,\).*expected \(8,\)"),
        (np.zeros((1, 8), dtype=np.float32), "shape"),
        ("fast", "not an array of numbers"),
    ],
)
def test_bad_actions_raise_clear_errors(bad, match):
    env = gym.make("SoftEel-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(bad)


def test_self_intersection_terminates_with_the_reason():
    env = gym.make("SoftEel-v0")
    kbar = np.full(8, 3.9)  # eight turns of 125 degrees: the body crosses itself
    x = body_from_curvature(kbar, np.full(9, 0.18))
    prev, prev_info = env.reset(seed=0, options={"x": x, "kbar": kbar})
    obs, reward, term, trunc, info = env.step(np.zeros(8, dtype=np.float32))
    assert term and not trunc
    assert info["x_position"] == prev_info["x_position"] and np.array_equal(info["kappa"], prev_info["kappa"])
    assert info["failure"] == "self_intersection"
    assert info["reward_failure"] == -10.0 and reward == pytest.approx(-10.0)
    assert env.observation_space.contains(obs) and np.array_equal(obs, prev)
    with pytest.raises(RuntimeError, match="terminated.*reset"):
        env.step(np.zeros(8, dtype=np.float32))
    env.reset(seed=0)
    assert not env.step(np.zeros(8, dtype=np.float32))[2]


def test_non_finite_state_terminates_with_a_finite_observation():
    # An explicit step far above the stability limit blows up; only the non-finite check stops it.
    integ = {
        "method": "symplectic_euler",
        "substeps": 1,
        "max_strain": 1e300,
        "check_self_intersection": False,
    }
    env = gym.make("SoftEel-v0", integrator=integ)
    env.reset(seed=0)
    for _ in range(1000):
        obs, _, term, trunc, info = env.step(np.zeros(8, dtype=np.float32))
        if term or trunc:
            break
    assert term, "the unstable integrator should have failed"
    assert info["failure"] == "non_finite_state"
    assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs)
    assert all(np.isfinite(v) for v in info["metrics"].values() if v != math.inf)


# --- reset ---------------------------------------------------------------------------------
def test_reset_options_set_the_initial_body_exactly():
    env = gym.make("SoftEel-v0")
    kbar = np.linspace(-0.5, 0.5, 8)
    x = body_from_curvature(kbar, np.full(9, 0.18), heading=0.3, com=(1.0, -2.0))
    v = np.full((10, 2), 0.01)
    obs, info = env.reset(seed=0, options={"x": x, "v": v, "kbar": kbar})
    sim = env.unwrapped.sim
    np.testing.assert_array_equal(sim.x, x)
    np.testing.assert_array_equal(sim.v, v)
    np.testing.assert_array_equal(sim.kbar, kbar)
    assert info["x_position"] == pytest.approx(1.0) and info["y_position"] == pytest.approx(-2.0)
    obs2, _ = env.reset(seed=99, options={"x": x, "v": v, "kbar": kbar})
    np.testing.assert_array_equal(obs, obs2)  # no noise
    with pytest.raises(ValueError, match="unknown"):
        env.reset(options={"kappa": kbar})
    with pytest.raises(ValueError, match="max_rest_curvature"):
        env.reset(options={"kbar": np.full(8, 5.0)})
    worm = gym.make("SoftWorm-v0")
    with pytest.raises(ValueError, match="rest_length_limits"):
        worm.reset(options={"lbar": np.full(9, 0.05)})


def test_goal_direction_option_turns_the_observation_and_the_reward():
    env = gym.make("SoftEel-v0", reset_noise_scale=0.0)
    obs, _ = env.reset(seed=0, options={"goal_direction": math.pi / 2})
    assert obs[-2:] == pytest.approx([0.0, 1.0], abs=1e-6)  # body along +x, goal to its left
    com0 = env.unwrapped.sim.com
    for _ in range(25):  # bending one way moves the centre of mass sideways
        _, _, _, _, info = env.step(np.full(8, 0.8, dtype=np.float32))
    dy = env.unwrapped.sim.com[1] - com0[1]
    assert abs(dy) > 1e-3 and info["metrics"]["distance"] == pytest.approx(dy, rel=1e-9)
    obs, _ = env.reset(seed=0)
    assert obs[-2:] == pytest.approx([1.0, 0.0], abs=1e-7)


def test_seeded_noisy_starts_differ_but_stay_small():
    env = gym.make("SoftEel-v0")
    starts = []
    for seed in (0, 1):
        env.reset(seed=seed)
        starts.append(env.unwrapped.sim.kappa)
    assert not np.array_equal(*starts)
    assert np.abs(starts[0]).max() <= 0.01 + 1e-12
    np.testing.assert_array_equal(env.unwrapped.sim.kbar, 0.0)


@pytest.mark.parametrize("env_id", ["SoftEel-v0", "SoftWorm-v0"])
def test_a_noisy_start_is_the_starting_state_of_the_docstring_drawn_by_rng_uniform(env_id):
    """The compiled start draws ``U(-s, s)`` as ``rng.uniform`` does, in the documented order, bit for bit."""
    s, worm = 0.05, env_id == "SoftWorm-v0"
    env = gym.make(env_id, reset_noise_scale=s, **({"rest_length_limits": [0.98, 1.02]} if worm else {}))
    base = env.unwrapped
    N, l0 = base.N, base.base_config.rod.edge_length
    for seed in range(4):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        kappa = rng.uniform(-s, s, N - 2)  # about the straight rest shape
        lbar = np.full(N - 1, l0)
        if worm:
            lbar = lbar * (1.0 + rng.uniform(-s, s, N - 1))
        x = body_from_curvature(kappa, lbar, heading=rng.uniform(-s, s))
        sim = base.sim
        np.testing.assert_array_equal(sim.x, x)
        np.testing.assert_array_equal(sim.v, 0.0)
        np.testing.assert_array_equal(sim.kbar, 0.0)
        np.testing.assert_array_equal(sim.lbar, np.clip(lbar, *base.lbar_limits) if worm else lbar)
        assert base.np_random.bit_generator.state == rng.bit_generator.state  # nothing more drawn
    if worm:  # a 5 % noise reaches the +-2 % limits: the body keeps its drawn lengths
        assert not np.array_equal(sim.lbar, lbar) and sim.lbar.max() == base.lbar_limits[1]


def test_randomization_draws_physics_per_episode_and_reports_it():
    ranges = {
        "E": [1.0e6, 3.0e6],
        "damping_bend": [0.0, 0.1],
        "damping_stretch": [0.0, 5.0],
        "rho": [900.0, 1100.0],
        "C_D": [1.0, 2.0],
        "C_A": [1.0, 2.0],
        "C_f": [0.2, 0.4],
    }
    env = gym.make("SoftEel-v0", randomize=ranges)
    _, info = env.reset(seed=0)
    drawn = info["randomized"]
    assert set(drawn) == set(ranges)
    for k, (lo, hi) in ranges.items():
        assert lo <= drawn[k] <= hi
    cfg = env.unwrapped.sim.config
    assert (cfg.rod.E, cfg.fluid.rho, cfg.fluid.C_D, cfg.fluid.C_f) == (
        drawn["E"],
        drawn["rho"],
        drawn["C_D"],
        drawn["C_f"],
    )
    sim_before = env.unwrapped.sim
    _, info2 = env.reset()
    assert info2["randomized"] != drawn
    assert env.unwrapped.sim is sim_before  # never rebuilt
    assert gym.make("SoftEel-v0").reset(seed=0)[1]["randomized"] == {}


def test_a_randomized_length_lag_reaches_the_length_actuators():
    """The drawn lag is the one the actuators follow.

    From rest, a commanded rate u gives ``lbar_dot = u (1 - exp(-h/tau))`` after one step
    (docs/model.md §3).
    """
    env = gym.make("SoftWorm-v0", randomize={"length_lag": [0.02, 0.2]}, reset_noise_scale=0.0)
    sim = env.unwrapped.sim
    taus = []
    for seed in (0, 1):
        tau = env.reset(seed=seed)[1]["randomized"]["length_lag"]
        assert 0.02 <= tau <= 0.2 and sim.config.rod.length_lag == tau
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        action[0] = 1.0  # the first edge at max_length_rate (0.3 m/s), the others held
        env.step(action)
        assert sim.lbar_dot[0] == pytest.approx(0.3 * (1.0 - math.exp(-sim.h / tau)), rel=1e-12)
        np.testing.assert_array_equal(sim.lbar_dot[1:], 0.0)
        taus.append(tau)
    assert taus[0] != taus[1]


# --- configuration ---------------------------------------------------------------------------
def test_yaml_configs_hold_the_defaults_and_keywords_override_them():
    eel = gym.make("SoftEel-v0", config="softeel").unwrapped  # a config shipped in the package, by name
    assert eel.settings == SwimSettings()
    worm = gym.make(
        "SoftWorm-v0", config=CONFIGS / "softworm.yaml", max_length_rate=0.4
    ).unwrapped  # or a path
    assert worm.settings == dataclasses.replace(InchSettings(), max_length_rate=0.4)
    assert worm.max_length_rate == 0.4
    # a simulator config file (with its medium key) is an env config too
    from soft_snake_gym.config import load_sim_config

    sim_file = CONFIGS / "eel.yaml"
    assert gym.make("SoftEel-v0", config=sim_file).unwrapped.sim.config == load_sim_config(sim_file)


def test_config_errors_name_the_key_and_the_fix(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("max_curvature_rat: 3.0\n")
    with pytest.raises(ConfigError, match="did you mean 'max_curvature_rate'"):
        gym.make("SoftEel-v0", config=bad)
    with pytest.raises(ConfigError, match="did you mean 'mu_s'"):
        gym.make("SoftWorm-v0", ground={"mus": 1.0})
    with pytest.raises(ConfigError, match="medium = 'ground'.*'water'"):
        gym.make("SoftEel-v0", config="worm")
    with pytest.raises(ConfigError, match="dt = 0.015 must be a positive integer multiple"):
        gym.make("SoftEel-v0", dt=0.015)
    with pytest.raises(ConfigError, match="rest_length_limits"):
        gym.make("SoftWorm-v0", rest_length_limits=[1.2, 1.5])
    with pytest.raises(
        ValueError, match="'sdirk2' does not run on the ground.*use 'backward_euler' or 'auto'"
    ):
        gym.make("SoftWorm-v0", integrator={"method": "sdirk2"})


def test_physics_keywords_reach_the_simulator():
    env = gym.make("SoftEel-v0", rod={"E_bend": 1.87e4}, fluid={"rho": 1025.0}, dt=0.03).unwrapped
    assert env.sim.config.rod.E_bend == 1.87e4 and env.sim.config.fluid.rho == 1025.0
    assert env.sim.config.medium == "water" and env.dt == pytest.approx(0.03) and env.n_substeps == 3
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full(8, 0.5, dtype=np.float32))
    assert info["time"] == pytest.approx(0.03)
    assert env.metadata["render_fps"] == 33


@pytest.mark.parametrize("cls, settings", [(SwimEnv, SwimSettings), (InchEnv, InchSettings)])
def test_docstring_argument_table_lists_every_keyword(cls, settings):
    table = cls.__doc__.split("## Arguments")[1].split("## Version History")[0]
    documented = set(re.findall(r"^\s*\| `(\w+)`", table, flags=re.M))
    keywords = {f.name for f in dataclasses.fields(settings)} | {"config", "render_mode", "preset"}
    assert documented == keywords
    for section in (
        "Description",
        "Action Space",
        "Observation Space",
        "Rewards",
        "Starting State",
        "Episode End",
        "Arguments",
        "Version History",
    ):
        assert f"## {section}" in cls.__doc__


# --- presets and the start on the gait --------------------------------------------------------
@pytest.mark.parametrize("env_id", IDS)
def test_preset_sets_the_physics_and_explicit_keywords_override_it(env_id, tmp_path):
    env = gym.make(env_id, preset="thesis", rod={"E_bend": 1e5}).unwrapped
    cfg = env.sim.config
    assert cfg.rod.damping_bend == 0.0 and cfg.rod.damping_stretch == 0.0 and cfg.rod.E_bend == 1e5
    assert cfg.fluid.added_mass == "kelasidi"
    assert env.sim.arrays.prm[L.P_DBEND] == 0.0 and env.sim.arrays.prm[L.P_DSTRETCH] == 0.0
    assert env.sim.arrays.prm[L.P_ADDED_MASS] == L.ADDED_MASS_KELASIDI
    env = gym.make(
        env_id, preset="thesis", rod={"damping_bend": 0.7}, fluid={"added_mass": "consistent"}
    ).unwrapped
    assert env.sim.config.rod.damping_bend == 0.7 and env.sim.arrays.prm[L.P_DBEND] == 0.7
    assert env.sim.config.rod.damping_stretch == 0.0
    assert env.sim.arrays.prm[L.P_ADDED_MASS] == L.ADDED_MASS_CONSISTENT
    # a config file may name the preset; its own keys and explicit keywords win over it
    path = tmp_path / "cfg.yaml"
    path.write_text("preset: thesis\nrod: {damping_stretch: 3.0}\n")
    env = gym.make(env_id, config=path, rod={"damping_stretch": 4.0, "damping_bend": 0.5}).unwrapped
    assert env.sim.config.rod.damping_stretch == 4.0 and env.sim.config.rod.damping_bend == 0.5
    assert env.sim.config.fluid.added_mass == "kelasidi"
    with pytest.raises(
        ConfigError, match=f"{env_id}: preset = 'thesiss' is unknown.*available presets: .*thesis"
    ):
        gym.make(env_id, preset="thesiss")


def test_batched_env_takes_the_preset_and_the_start_on_gait():
    from soft_snake_gym.envs import SwimVectorEnv

    venv = SwimVectorEnv(num_envs=2, preset="thesis", start_on_gait={"alpha": 0.8, "psi0": 1.0})
    assert all(sim.config.fluid.added_mass == "kelasidi" for sim in venv.batch.sims)
    obs, _ = venv.reset(seed=[0, 1])
    kappa_des = serpenoid(serpenoid_phase(0.0, 8, 0.0, math.pi / 4, 1.0), 0.0, 0.8)[0]
    np.testing.assert_allclose(obs[:, :8], np.tile(kappa_des, (2, 1)), rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(obs[:, 8:16], 0.0)  # at rest: no curvature rate
    venv.close()


def test_start_on_gait_is_at_rest_with_the_desired_curvatures_and_no_noise():
    from soft_snake_gym.policies import CurvaturePID

    gait = {"alpha": math.pi / 3, "omega": 2.5, "delta": 0.7, "gamma": 0.1, "psi0": 0.4}
    env = gym.make("SoftEel-v0", start_on_gait=gait, reset_noise_scale=0.05)
    u = env.unwrapped
    kappa_des = serpenoid(serpenoid_phase(0.0, 8, 2.5, 0.7, 0.4), 2.5, math.pi / 3, 0.1)[0]
    bodies = []
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        np.testing.assert_allclose(u.sim.kappa, kappa_des, rtol=0, atol=1e-12)  # measured
        np.testing.assert_array_equal(u.sim.kbar, kappa_des)  # rest shape on the gait too
        np.testing.assert_array_equal(u.sim.v, 0.0)
        np.testing.assert_allclose(u.sim.com, 0.0, atol=1e-12)
        bodies.append(u.sim.x)
    np.testing.assert_array_equal(bodies[0], bodies[1])  # no seeded noise
    # the same gait's controller sees no error at its first step
    pid = CurvaturePID(env, **gait)
    pid.predict(obs)
    assert pid.last_error.max() < 1e-6
    # missing fields take the thesis gait (alpha = pi/6, delta = 2 pi/(N-2), psi0 = 0)
    env = gym.make("SoftEel-v0", start_on_gait={})
    env.reset(seed=0)
    np.testing.assert_allclose(
        env.unwrapped.sim.kappa,
        serpenoid(serpenoid_phase(0.0, 8, 0.0, math.pi / 4), 0.0, math.pi / 6)[0],
        atol=1e-12,
    )


@pytest.mark.parametrize(
    ("env_id", "kwargs", "message"),
    [
        ("SoftEel-v0", {"start_on_gait": {"alpha": -0.1}}, r"alpha = -0.1 rad must be in \[0, pi\)"),
        (
            "SoftEel-v0",
            {"start_on_gait": {"psi0": float("nan")}},
            "start_on_gait.psi0 = nan must be a finite number",
        ),
        ("SoftEel-v0", {"start_on_gait": {"omga": 2.0}}, "did you mean 'omega'"),
        ("SoftEel-v0", {"start_on_gait": True}, "start_on_gait must be a mapping"),
        (
            "SoftEel-v0",
            {"start_on_gait": {"alpha": 1.6}},
            r"self-intersecting body at t = 0.*keep alpha below 1.59",
        ),
        (
            "SoftEel-v0",
            {"start_on_gait": {"alpha": 1.2}, "max_rest_curvature": 1.0},
            "beyond max_rest_curvature = 1.0",
        ),
        ("SoftEel-v0", {"start_on_gait": {}, "initial_shape": "serpenoid"}, "both set the start; use one"),
        ("SoftWorm-v0", {"start_on_gait": {}}, "unknown key 'start_on_gait'"),
    ],
)
def test_start_on_gait_bad_values_are_explained(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make(env_id, **kwargs)
