"""The batched vector env.

Gymnasium's vector API, autoreset, bit-for-bit equality with the single env, SB3 (PPO, VecNormalize,
evaluate_policy) and clear errors.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.spaces import Box
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.wrappers.vector import RecordEpisodeStatistics

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs import InchEnv, SoftVectorEnv, SwimEnv
from soft_snake_gym.envs.task import T_GOAL

IDS = ["SoftEel-v0", "SoftWorm-v0"]
# settings under which random actions end episodes both ways within a few hundred steps: the
# eel folds onto itself (a failure), the worm hits a short time limit; both randomize physics
ENDS = {
    "SoftEel-v0": dict(max_curvature_rate=30.0, randomize={"E": [1e6, 3e6], "rho": [900, 1100]}),
    "SoftWorm-v0": dict(randomize={"mu_s": [0.8, 1.2], "mu_d": [0.5, 0.8]}, dt=0.02),
    # targets drawn about the success radius away: some are reached (terminated with success)
    "SoftEelGoal-v0": dict(max_curvature_rate=30.0, target_distance=[0.25, 0.4], success_radius=0.3),
    "SoftEelPath-v0": dict(max_curvature_rate=30.0, path="sine", randomize={"E": [1e6, 3e6]}),
}
ENDS["SoftEel-v0-bdf2"] = dict(ENDS["SoftEel-v0"], integrator={"method": "bdf2"})
ENDS["SoftEel-v0-sub3"] = dict(ENDS["SoftEel-v0"], integrator={"substeps": 3})


def _actions(space: Box, steps: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (steps,) + space.shape).astype(np.float32)


def _drop_times(infos: dict) -> dict:
    """Episode wall-clock times differ between two runs; everything else must not."""
    infos = dict(infos)
    if "episode" in infos:
        infos["episode"] = {k: v for k, v in infos["episode"].items() if k != "t"}
    return infos


@pytest.mark.parametrize("env_id", IDS)
def test_make_vec_returns_the_batched_env_with_batched_spaces(env_id):
    venv = gym.make_vec(env_id, num_envs=3)  # Gymnasium 1.x prefers the vector entry point
    assert isinstance(venv, SoftVectorEnv) and venv.env_id == env_id
    assert venv.spec.id == env_id and venv.max_episode_steps == 1000
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    single = gym.make(env_id)
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.observation_space.shape == (3,) + single.observation_space.shape
    assert venv.action_space.shape == (3,) + single.action_space.shape
    assert isinstance(venv.envs[0], SwimEnv if env_id == "SoftEel-v0" else InchEnv)
    same = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    assert isinstance(same, SoftVectorEnv)
    assert isinstance(gym.make_vec(env_id, num_envs=2, vectorization_mode="sync"), SyncVectorEnv)


@pytest.mark.parametrize(
    ("env_id", "mode"),
    [
        (i, AutoresetMode.NEXT_STEP)
        for i in IDS + ["SoftEelGoal-v0", "SoftEelPath-v0", "SoftEel-v0-bdf2", "SoftEel-v0-sub3"]
    ]
    + [("SoftEel-v0", AutoresetMode.SAME_STEP), ("SoftEelGoal-v0", AutoresetMode.SAME_STEP)],
)
def test_matches_sync_vector_env_of_single_envs_bit_for_bit_over_500_steps(env_id, mode):
    """Robot i seeded s + i, with the same actions, is the single env seeded s + i.

    Obs, rewards, ends, every info entry and the episode statistics, across failures, time limits
    and autoresets (with physics randomization drawn anew at each), in both autoreset modes; under
    BDF2, whose history each reset starts anew; and with three SDIRK2 sub-steps per step.
    """
    # a block of 16 robots stepped together (envs.task.block_step) and three one by one
    n, steps, kw = 19, 500 if mode == AutoresetMode.NEXT_STEP else 250, ENDS[env_id]
    env_id = env_id.removesuffix("-bdf2").removesuffix("-sub3")
    batched = gym.make_vec(env_id, num_envs=n, max_episode_steps=90, autoreset_mode=mode, **kw)
    sync = RecordEpisodeStatistics(
        gym.make_vec(
            env_id,
            num_envs=n,
            vectorization_mode="sync",
            max_episode_steps=90,
            vector_kwargs={"autoreset_mode": mode},
            **kw,
        )
    )
    obs_b, info_b = batched.reset(seed=11)
    obs_s, info_s = sync.reset(seed=11)
    assert data_equivalence(obs_b, obs_s, exact=True)
    assert data_equivalence(info_b, info_s, exact=True)
    assert not np.array_equal(obs_b[0], obs_b[1])  # the robots really differ
    ends = {"terminated": 0, "truncated": 0}
    for a in _actions(batched.action_space, steps, seed=2):
        out_b = batched.step(a)
        out_s = sync.step(a)
        for x, y, what in zip(
            out_b[:4], out_s[:4], ("obs", "reward", "terminated", "truncated"), strict=True
        ):
            assert data_equivalence(x, y, exact=True), what
        assert data_equivalence(_drop_times(out_b[4]), _drop_times(out_s[4]), exact=True)
        assert np.array_equal(out_b[0].view(np.int32), out_s[0].view(np.int32))  # signed zeros too
        assert np.array_equal(out_b[1].view(np.int64), out_s[1].view(np.int64))
        ends["terminated"] += int(out_b[2].sum())
        ends["truncated"] += int(out_b[3].sum())
    if env_id in ("SoftEel-v0", "SoftEelGoal-v0"):
        assert ends["terminated"] >= 2  # failures (or targets reached) happened inside the run
    assert ends["truncated"] >= 2


@pytest.mark.parametrize("env_id", IDS)
def test_returns_follow_the_batched_spaces_and_types(env_id):
    venv = SoftVectorEnv(env_id, 3)
    obs, info = venv.reset(seed=0)
    assert obs.dtype == np.float32 and venv.observation_space.contains(obs)
    assert isinstance(info, dict) and info["_x_position"].all()
    for a in _actions(venv.action_space, 5, seed=0):
        obs, rew, term, trunc, info = venv.step(np.where(a >= 0, 3.0, -3.0))  # clipped to +-1
        assert venv.observation_space.contains(obs)
        assert rew.shape == (3,) and rew.dtype == np.float64
        assert term.dtype == np.bool_ and trunc.dtype == np.bool_ and term.shape == trunc.shape == (3,)
        n_act = venv.single_action_space.shape[0]
        assert np.all(np.abs(info["reward_ctrl"] + venv.settings.ctrl_cost_weight * n_act) < 1e-12)
    venv.close()


def test_autoreset_next_step_returns_the_last_obs_then_a_reset_robot():
    venv = SoftVectorEnv("SoftEel-v0", 2, max_episode_steps=3)
    venv.reset(seed=0)
    a = np.full((2, 8), 0.5, np.float32)
    returns = np.zeros(2)
    for _ in range(2):
        _, rew, term, trunc, _ = venv.step(a)
        returns += rew
        assert not (term.any() or trunc.any())
    obs, rew, term, trunc, info = venv.step(a)
    returns += rew
    assert trunc.all() and not term.any()
    assert np.array_equal(info["episode"]["l"], [3, 3]) and info["_episode"].all()
    np.testing.assert_allclose(info["episode"]["r"], returns)
    assert np.all(info["time"] == pytest.approx(0.03))
    obs2, rew2, term2, trunc2, info2 = venv.step(np.full((2, 8), np.nan, np.float32))  # ignored
    assert np.array_equal(rew2, [0.0, 0.0]) and not (term2.any() or trunc2.any())
    assert np.array_equal(info2["time"], [0.0, 0.0]) and "forward_speed" not in info2
    assert info2["_randomized"].all()
    assert not np.array_equal(obs2, obs)  # a fresh, noisy straight body, not the bent one
    np.testing.assert_array_equal(obs2[:, 16:24], 0.0)  # rest curvatures back to straight


def test_a_time_limit_set_after_construction_is_the_one_that_truncates():
    venv = SoftVectorEnv("SoftEel-v0", 2)
    venv.reset(seed=0)
    venv.max_episode_steps = 2  # a public attribute: the step reads it, not a copy made at construction
    a = np.zeros((2, 8), np.float32)
    assert not venv.step(a)[3].any()
    assert venv.step(a)[3].all()


def test_autoreset_same_step_gives_final_obs_and_final_info():
    venv = SoftVectorEnv("SoftEel-v0", 3, max_episode_steps=2, autoreset_mode="SameStep")
    venv.reset(seed=5)
    a = np.full((3, 8), 0.3, np.float32)
    last, *_ = venv.step(a)
    obs, rew, term, trunc, info = venv.step(a)
    assert trunc.all() and info["_final_obs"].all()
    assert np.all(info["final_info"]["time"] == pytest.approx(0.02))
    assert np.all(info["time"] == 0.0)  # the reset robots' state
    assert np.all(rew != 0.0)  # the last step's reward, not a reset's zero
    assert not np.array_equal(info["final_obs"][0], obs[0])
    assert np.array_equal(info["episode"]["l"], [2, 2, 2])
    obs3, *_ = venv.step(a)  # no reset step in between: the new episodes move on
    assert not np.array_equal(obs3, obs)


def test_threads_do_not_change_a_bit():
    a = _actions(Box(-1, 1, (35, 8)), 150, seed=4)  # two blocks of 16 robots and three more
    runs = []
    for threads in (1, 2):
        venv = SoftVectorEnv(
            "SoftEel-v0", 35, num_threads=threads, max_episode_steps=40, max_curvature_rate=30.0
        )
        assert venv.num_threads == threads
        obs, _ = venv.reset(seed=3)
        trace = [obs]
        for act in a:
            obs, rew, term, trunc, _ = venv.step(act)
            trace += [obs, rew, term, trunc]
        runs.append(trace)
    assert all(np.array_equal(x, y) for x, y in zip(*runs, strict=True))


def test_default_threads_follow_the_robot_count():
    import numba

    assert SoftVectorEnv("SoftEel-v0", 8).num_threads == 1
    assert SoftVectorEnv("SoftEel-v0", 128).num_threads == min(2, numba.config.NUMBA_NUM_THREADS)


def test_reset_accepts_one_seed_per_robot_and_options():
    venv = SoftVectorEnv("SoftEel-v0", 2)
    obs, _ = venv.reset(seed=[7, 3])
    single = gym.make("SoftEel-v0")
    assert np.array_equal(obs[0], single.reset(seed=7)[0])
    assert np.array_equal(obs[1], single.reset(seed=3)[0])
    _, info = venv.reset(seed=0, options={"goal_direction": 1.0})
    assert np.allclose(venv.batch.task.tp[:, T_GOAL], 1.0)
    assert info["heading"].shape == (2,)


def test_bad_arguments_are_explained():
    with pytest.raises(
        ValueError, match=r"num_envs = 0 must be an integer in \[1, inf\] \(the number of robots\)"
    ):
        SoftVectorEnv("SoftEel-v0", 0)
    with pytest.raises(ValueError, match=r"num_threads = 0 must be an integer in \[1, "):
        SoftVectorEnv("SoftEel-v0", 2, num_threads=0)
    with pytest.raises(ValueError, match=r"num_threads = 99"):
        SoftVectorEnv("SoftEel-v0", 2, num_threads=99)
    with pytest.raises(ValueError, match=r"env_id = 'Swimmer-v5' has no batched version"):
        SoftVectorEnv("Swimmer-v5", 2)
    with pytest.raises(ValueError, match=r"autoreset_mode = .*Disabled"):
        SoftVectorEnv("SoftEel-v0", 2, autoreset_mode=AutoresetMode.DISABLED)
    with pytest.raises(ValueError, match=r"max_episode_steps = 0"):
        SoftVectorEnv("SoftEel-v0", 2, max_episode_steps=0)
    with pytest.raises(ValueError, match=r"render a single env"):
        SoftVectorEnv("SoftEel-v0", 2, render_mode="rgb_array")
    with pytest.raises(Exception, match=r"max_curvature_rat"):
        SoftVectorEnv("SoftEel-v0", 2, max_curvature_rat=3.0)  # a typo, named
    venv = SoftVectorEnv("SoftEel-v0", 2)
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        venv.step(np.zeros((2, 8)))
    obs, _ = venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(8,\); expected \(2, 8\)"):
        venv.step(np.zeros(8))
    bad = np.zeros((2, 8))
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"non-finite entries for robots \[1\]"):
        venv.step(bad)
    with pytest.raises(ValueError, match=r"not an array of numbers"):
        venv.step([["a"] * 8] * 2)
    assert np.array_equal(venv.step(np.zeros((2, 8)))[0].shape, (2, 28))  # still usable


def test_a_refused_step_changes_nothing_not_even_the_resets_it_was_due_to_make():
    """Bad actions are refused before any work: a robot due to start again is not reset twice."""

    def run(refused: bool) -> SoftVectorEnv:
        venv = SoftVectorEnv("SoftEel-v0", 2, max_episode_steps=2)
        venv.reset(seed=4)
        a = np.full((2, 8), 0.3)
        venv.step(a)
        venv.reset_robot(1, seed=9)  # robot 1's episode starts a step later than robot 0's
        _, _, _, truncated, _ = venv.step(a)
        assert truncated.tolist() == [True, False]  # robot 0 starts again in the next step
        if refused:
            bad = a.copy()
            bad[1, 0] = np.inf  # robot 1 steps in it
            with pytest.raises(ValueError, match=r"non-finite entries for robots \[1\]"):
                venv.step(bad)
        venv.step(a)
        return venv

    plain, refused = run(False), run(True)
    for arrays in ("sim", "task"):
        assert getattr(plain.batch, arrays).f.tobytes() == getattr(refused.batch, arrays).f.tobytes()
    assert plain.envs[0].np_random.bit_generator.state == refused.envs[0].np_random.bit_generator.state


def test_returned_arrays_are_not_the_env_buffers():
    venv = SoftVectorEnv("SoftEel-v0", 2)
    obs, _ = venv.reset(seed=0)
    obs2, rew, _, _, info = venv.step(np.zeros((2, 8), np.float32))
    keep = obs2.copy(), rew.copy(), info["kappa"].copy()
    obs2[:] = 99
    rew[:] = 99
    info["kappa"][:] = 99
    obs3, rew3, _, _, info3 = venv.step(np.zeros((2, 8), np.float32))
    assert not np.array_equal(obs3, obs2) and not np.array_equal(rew3, rew)
    assert np.all(np.abs(info3["kappa"] - keep[2]) < 1.0)


# --- Stable-Baselines3 ---------------------------------------------------------------------------
def test_sb3_adapter_matches_dummy_vec_env_of_single_envs():
    """SoftVecEnv is bitwise SB3's DummyVecEnv over Monitor-wrapped single envs (make_vec_env).

    Terminal observations and time-limit flags included.
    """
    from stable_baselines3.common.env_util import make_vec_env

    from soft_snake_gym.sb3 import SoftVecEnv

    kw = dict(max_curvature_rate=30.0)
    ours = SoftVecEnv("SoftEel-v0", n_envs=3, seed=4, max_episode_steps=50, **kw)
    ref = make_vec_env("SoftEel-v0", n_envs=3, seed=4, env_kwargs=dict(max_episode_steps=50, **kw))
    assert np.array_equal(ours.reset(), ref.reset())
    ends = 0
    for a in _actions(Box(-1, 1, (3, 8)), 200, seed=9):
        o1, r1, d1, i1 = ours.step(a)
        o2, r2, d2, i2 = ref.step(a)
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(d1, d2)
        for x, y, d in zip(i1, i2, d1, strict=True):
            if d:
                ends += 1
                assert np.array_equal(x["terminal_observation"], y["terminal_observation"])
                assert x["TimeLimit.truncated"] == y.get("TimeLimit.truncated", False)
                assert x["episode"]["r"] == pytest.approx(y["episode"]["r"], rel=1e-6)
                assert x["episode"]["l"] == y["episode"]["l"]
                assert x["metrics"] == y["metrics"] and x["failure"] == y["failure"]
    assert ends >= 3


def test_sb3_ppo_trains_and_vecnormalize_and_evaluate_policy_run(tmp_path):
    from stable_baselines3 import PPO
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecNormalize

    from soft_snake_gym.sb3 import SoftVecEnv

    env = VecNormalize(SoftVecEnv("SoftEel-v0", n_envs=4, seed=0, max_episode_steps=64))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.set_logger(Logger(folder=None, output_formats=[]))  # no /tmp/SB3-<date> left behind
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(512)
    assert model.num_timesteps == 512
    assert any(
        not np.array_equal(b.numpy(), p.detach().numpy())
        for b, p in zip(before, model.policy.parameters(), strict=True)
    )
    assert len(model.ep_info_buffer) == 8  # episode statistics reach SB3's logger
    assert env.obs_rms.count > 512  # VecNormalize saw every observation
    env.save(tmp_path / "vecnormalize.pkl")
    env.training = False
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "not wrapped with a Monitor" warning
        rewards, lengths = evaluate_policy(model, env, n_eval_episodes=4, return_episode_rewards=True)
    assert lengths == [64, 64, 64, 64] and all(np.isfinite(rewards))


def test_sb3_step_info_gives_the_single_env_info():
    from soft_snake_gym.sb3 import SoftVecEnv

    env = SoftVecEnv("SoftWorm-v0", n_envs=2, seed=1, step_info=True)
    single = gym.make("SoftWorm-v0")
    env.reset()
    single.reset(seed=2)
    a = _actions(Box(-1, 1, (2, 9)), 3, seed=1)
    for act in a:
        _, _, _, infos = env.step(act)
        _, _, _, _, info = single.step(act[1])
    assert data_equivalence(infos[1], info, exact=True)


def test_training_config_offers_the_batched_env():
    from soft_snake_gym.sb3 import SoftVecEnv
    from soft_snake_gym.training import TrainConfig, make_train_env

    env = make_train_env(TrainConfig(env_id="SoftWorm-v0", vec_env="batched", n_envs=3), seed=5)
    assert isinstance(env, SoftVecEnv) and env.num_envs == 3
    obs = env.reset()
    single = gym.make("SoftWorm-v0")
    assert np.array_equal(obs[2], single.reset(seed=7)[0])  # seeded seed + i, as make_vec_env
