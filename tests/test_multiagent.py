"""The segment team: PettingZoo's API, equality with SoftEel-v0, local terms, the SB3 adapter, bad input."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pettingzoo.test as pettingzoo_test  # noqa: E402
import pytest

import soft_snake_gym  # noqa: F401  registers the ids
from soft_snake_gym.envs import SwimEnv
from soft_snake_gym.multiagent import SegmentsEnv, eel_segments_v0
from soft_snake_gym.multiagent.policies import CentralizedTeam, DecentralizedTeam
from soft_snake_gym.physics import forces, geometry
from soft_snake_gym.policies import CurvaturePID, DecentralizedPhasePID


def test_pettingzoo_parallel_api_and_seed_tests_pass():
    pettingzoo_test.parallel_api_test(eel_segments_v0.parallel_env(max_cycles=40), num_cycles=60)
    pettingzoo_test.parallel_seed_test(lambda: eel_segments_v0.parallel_env(max_cycles=40))
    pettingzoo_test.api_test(eel_segments_v0.env(max_cycles=20), num_cycles=30)


def _rollout_team(policy_factory, steps, seed=3, **kwargs):
    """The PettingZoo env driven by a team policy; per step the global state and the agents' infos."""
    par = eel_segments_v0.parallel_env(**kwargs)
    policy = policy_factory(par.team)
    obs, _ = par.reset(seed=seed)
    state, start = None, np.ones(1, bool)
    states, speeds, x = [], [], []
    for _ in range(steps):
        team_obs = np.stack([obs[a] for a in par.agents])[None]
        act, state = policy.predict(team_obs, state, start)
        start = np.zeros(1, bool)
        obs, rewards, term, trunc, infos = par.step({a: act[0, i : i + 1] for i, a in enumerate(par.agents)})
        states.append(par.state())
        speeds.append(infos["node_1"]["forward_speed"])
        x.append(par.team.sim.x.copy())
    return np.array(states), np.array(speeds), np.array(x), infos["node_1"]["metrics"]


def _rollout_eel(policy_cls, steps, seed=3, **kwargs):
    env = SwimEnv(**kwargs)
    policy = policy_cls(env)
    obs, _ = env.reset(seed=seed)
    state, start = None, np.ones(1, bool)
    states, speeds, x = [], [], []
    for _ in range(steps):
        act, state = policy.predict(obs[None], state, start)
        start = np.zeros(1, bool)
        obs, _, _, _, info = env.step(act[0])
        states.append(obs)
        speeds.append(info["forward_speed"])
        x.append(env.sim.x.copy())
    return np.array(states), np.array(speeds), np.array(x), info["metrics"]


@pytest.mark.parametrize(
    ("team_cls", "baseline"), [(CentralizedTeam, CurvaturePID), (DecentralizedTeam, DecentralizedPhasePID)]
)
def test_the_team_under_a_baseline_is_softeel_under_it_bit_for_bit(team_cls, baseline):
    steps = 400
    team = _rollout_team(lambda t: team_cls(baseline(t.swim), t), steps, randomize={"C_D": [1.5, 2.0]})
    eel = _rollout_eel(baseline, steps, randomize={"C_D": [1.5, 2.0]})
    for a, b in zip(team[:3], eel[:3], strict=True):
        np.testing.assert_array_equal(a, b)
    assert team[3] == eel[3]
    assert team[3]["distance"] > 0.2  # it swims: the comparison is of a real gait


def test_local_powers_add_up_to_the_actuator_power_at_the_end_of_the_step():
    env = SegmentsEnv(N=12)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(30):
        env.step(rng.uniform(-1, 1, 10).astype(np.float32))
    _, reward, _, _, info = env.step(rng.uniform(-1, 1, 10).astype(np.float32))
    s, t = env.sim.arrays, env.swim.task
    geo = np.zeros((2, s.q.size))
    geometry.edge_geometry(s.q, geo)
    total = forces.actuator_power(s.q, s.kbar, s.lbar, t.uk, np.zeros(11), s.prm, geo)
    weight = env.swim.settings.energy_cost_weight
    local = info["agent_reward_energy"] / -weight  # |P_j|
    signed = -s.prm[forces.P_EI] / s.lbar[0] * (env.swim.task.raw[:10] - s.kbar) * t.uk
    np.testing.assert_allclose(np.abs(signed), local, rtol=1e-12)
    assert signed.sum() == pytest.approx(total, rel=1e-10)
    assert abs(total) > 1.0  # a real power, not zeros
    # the team reward is the shared term plus the local ones
    expected = info["reward_forward"] + info["agent_reward_energy"].sum() + info["agent_reward_ctrl"].sum()
    assert info["agent_rewards"] == pytest.approx(
        info["reward_forward"] + info["agent_reward_energy"] + info["agent_reward_ctrl"]
    )
    assert reward == pytest.approx(expected)


def test_local_observation_reads_own_and_neighbour_entries_of_the_softeel_observation():
    env = SegmentsEnv(N=8, neighbors="both", closure="open", observe_goal=True)
    obs, _ = env.reset(seed=1)
    swim = env.swim.task.obs
    k = 6
    assert list(env.layout.structure)[:3] == ["kappa", "kappa_dot", "kbar"]
    assert obs.shape == (k, 9)
    for j in range(k):
        assert obs[j, 0] == swim[j] and obs[j, 1] == swim[k + j] and obs[j, 2] == swim[2 * k + j]
        assert obs[j, 3] == (swim[j + 1] if j + 1 < k else 0.0)  # head-ward neighbour, open end
        assert obs[j, 5] == (swim[j - 1] if j > 0 else 0.0)  # tail-ward neighbour
        np.testing.assert_array_equal(obs[j, 7:], swim[3 * k + 2 :])  # goal direction
    ring = SegmentsEnv(N=8)
    obs, _ = ring.reset(seed=1)
    assert obs[-1, 3] == ring.swim.task.obs[0] and obs[0, 5] == ring.swim.task.obs[k - 1]
    # a lost message: node 3's neighbours read zeros for it, node 3 itself still measures itself
    ring.lost_messages = np.zeros(k, bool)
    ring.lost_messages[2] = True
    lost = ring.observe()
    assert lost[2, 0] == obs[2, 0] != 0.0
    assert lost[1, 3] == 0.0 and lost[1, 4] == 0.0 and lost[3, 5] == 0.0 and lost[3, 6] == 0.0
    assert lost[0, 3] == obs[0, 3] != 0.0


def test_the_batched_adapter_gives_each_robot_the_single_env_numbers():
    from soft_snake_gym.sb3 import SegmentVecEnv

    venv = SegmentVecEnv(16, seed=5, max_episode_steps=30, N=10)
    obs = venv.reset()
    rng = np.random.default_rng(2)
    acts = rng.uniform(-1, 1, (31, 16, 1)).astype(np.float32)
    single = SegmentsEnv(N=10)
    o1, _ = single.reset(seed=6)  # robot 1
    np.testing.assert_array_equal(obs[8:], o1)
    returns = []
    for n in range(30):  # the 30th step ends the episodes by the time limit
        obs, rewards, dones, infos = venv.step(acts[n])
        returns.append(rewards[9])
        o1, _, _, _, info1 = single.step(acts[n, 8:, 0])
        if n < 29:
            np.testing.assert_array_equal(obs[8:], o1)
        np.testing.assert_allclose(rewards[8:], info1["agent_rewards"], rtol=1e-6)
        assert dones.all() == (n == 29)
        if n == 29:  # the time limit: every slot of both robots ends, with its last observation
            np.testing.assert_array_equal(infos[9]["terminal_observation"], o1[1])
            assert infos[9]["TimeLimit.truncated"] and infos[9]["episode"]["l"] == 30
            return_1 = infos[9]["episode"]["r"]
            assert return_1 == pytest.approx(float(np.sum(returns)), rel=1e-5)
    with pytest.raises(ValueError, match="multiple of the agents per robot"):
        SegmentVecEnv(12, N=10)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p.observation_space("node_9"), "node_9.*does not exist.*node_1 ... node_8"),
        (lambda p: p.action_space("head"), "'head' does not exist"),
        (lambda p: p.step({a: 0.0 for a in p.agents[:-1]}), r"missing \['node_8'\]"),
        (lambda p: p.step({**{a: 0.0 for a in p.agents}, "node_11": 0.0}), r"unknown \['node_11'\]"),
        (lambda p: p.step({a: np.zeros(2) for a in p.agents}), "action of node_1.*shape \\(1,\\)"),
        (lambda p: p.step({a: np.nan for a in p.agents}), "action of node_1.*finite"),
        (lambda p: p.step([0.0] * 8), "must be a dict"),
    ],
)
def test_bad_agent_input_gets_a_clear_error(make, message):
    par = eel_segments_v0.parallel_env()
    par.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        make(par)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"N": 2}, "N = 2"),
        ({"N": 12, "rod": {"N": 10}}, "N = 12 and rod.N = 10 disagree"),
        ({"neighbors": "left"}, "neighbors = 'left' is unknown; use one of both, head, tail, none"),
        ({"closure": "ring"}, "closure = 'ring' is unknown"),
        ({"observe_goal": "yes"}, "observe_goal = 'yes' must be True or False"),
        ({"max_cycles": 0}, "max_cycles"),
    ],
)
def test_bad_keywords_get_a_clear_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        eel_segments_v0.parallel_env(**kwargs)


def test_body_length_is_a_keyword_and_gym_make_builds_the_team():
    par = eel_segments_v0.parallel_env(N=14)
    assert par.possible_agents[-1] == "node_12" and len(par.possible_agents) == 12
    env = gym.make("SoftEelSegments-v0", N=20)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (18, 7) and env.action_space.shape == (18,)
    assert env.spec.max_episode_steps == 1000


def test_a_failed_actuator_holds_its_rest_curvature_and_a_lost_message_reaches_only_neighbours():
    from soft_snake_gym.studies.robustness import Perturbation, Perturbed

    env = Perturbed(SegmentsEnv(N=10), Perturbation(failed_node=3, lost_node=5, loss_fraction=1.0))
    obs, _ = env.reset(seed=0)
    kbar0 = env.unwrapped.sim.kbar.copy()
    for _ in range(50):
        obs, *_ = env.step(np.full(8, 0.5, np.float32))
    kbar = env.unwrapped.sim.kbar
    assert kbar[2] == kbar0[2]  # node 3 never moved its rest curvature
    assert np.all(np.abs(kbar[[0, 1, 3, 4]] - kbar0[[0, 1, 3, 4]]) > 0.1)  # the others did
    assert obs[4, 0] != 0.0  # node 5 measures itself
    assert obs[3, 3] == obs[3, 4] == 0.0 and obs[5, 5] == obs[5, 6] == 0.0  # its neighbours lost it
    eel = Perturbed(SwimEnv(), Perturbation(lost_node=5, loss_fraction=1.0))
    obs, _ = eel.reset(seed=0)
    obs, *_ = eel.step(np.full(8, 0.5, np.float32))
    assert obs[4] == obs[12] == 0.0 and obs[3] != 0.0  # the centre lost node 5's kappa and rate
    with pytest.raises(ValueError, match="node_9.*does not exist"):
        Perturbed(SegmentsEnv(N=10), Perturbation(failed_node=9))


@pytest.mark.slow
def test_robustness_study_writes_tables_and_figures_and_a_failure_slows_the_eel(tmp_path):
    from soft_snake_gym.studies.robustness import default_controllers, format_table, run_experiment

    controllers = default_controllers(keys=("decentralized",))
    kwargs = {"max_episode_steps": 600}
    rows = run_experiment("failure", tmp_path, controllers, episodes=1, env_kwargs=kwargs)
    assert (tmp_path / "failure.csv").is_file() and (tmp_path / "failure.png").is_file()
    speed = {r["setting"]: float(r["average_speed_mean"]) for r in rows}
    assert len(speed) == 9  # none, node_1 ... node_8
    assert speed["none"] > 0.05
    assert min(speed[f"node_{j}"] for j in range(1, 9)) < 0.5 * speed["none"]  # a failure near the head
    assert "| node_2 |" in format_table("failure", rows)
    again = run_experiment("failure", tmp_path, controllers, episodes=1, n_nodes=6, env_kwargs=kwargs)
    assert again == rows  # read back from the CSV, nothing run again


@pytest.mark.slow
def test_shared_policy_imitates_trains_and_runs_at_other_body_lengths(tmp_path):
    import csv
    import pickle

    from soft_snake_gym.agents import make_policy
    from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
    from soft_snake_gym.multiagent.policies import SharedLocalPolicy
    from soft_snake_gym.training import load_train_config, train

    overrides = {
        "n_envs": 16,
        "n_timesteps": 512,
        "n_steps": 32,
        "batch_size": 128,
        "n_epochs": 1,
        "learning_rate": 1e-5,
        "eval_freq": 512,
        "eval_episodes": 1,
        "checkpoint_freq": 512,
        "imitate": "decentralized",
        # the copy of the stateful chain stalls from some data sets (measured, 3 to 8 episodes:
        # backward Euler stalls at 4 and 8, SDIRK2 at 3 and 8); 6 swims under both
        "imitate_episodes": 6,
        "env_kwargs": {"max_episode_steps": 400},
    }
    run = tmp_path / "run"
    train(load_train_config("SoftEelSegments-v0", overrides=overrides), run, progress=False)
    with open(run / "vecnormalize.pkl", "rb") as fh:  # the teacher's statistics, not moved by PPO's rollouts
        stats = pickle.load(fh)
    assert not stats.training and stats.obs_rms.count == 6 * 400 * 8  # episodes x steps x agents
    row = list(csv.DictReader(open(run / "learning_curve.csv")))[0]  # at the first step: imitation only
    # the imitated shared policy swims like the decentralized PID it copied
    assert float(row["baseline_average_speed"]) > 0.05
    assert float(row["average_speed_mean"]) > 0.7 * float(row["baseline_average_speed"])
    env = make_eval_env("SoftEelSegments-v0", seed=0, env_kwargs={"N": 14, "max_episode_steps": 300})
    policy = make_policy(str(run), env)
    assert isinstance(policy, SharedLocalPolicy)
    (summary,) = [summarize(evaluate(policy, env, episodes=1))]
    assert summary["average_speed"][0] > 0.0  # a policy of one node runs on a longer body


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["robustness", "wobble"], "unknown experiment 'wobble'; choose from failure, message, length"),
        (["robustness", "failure", "--controllers", "mpc"], "controller 'mpc' is unknown"),
        (["robustness", "message", "--lost-node", "9", "--controllers", "pid"], "node_9"),
        (["robustness", "message", "--fractions", "1.5", "--controllers", "pid"], "loss fraction"),
        (["compare", "SoftEelSegments-v0", "--policies", "pdi"], "unknown policy 'pdi'"),
    ],
)
def test_bad_study_input_gets_one_line_and_exit_2(args, message, tmp_path, capsys):
    from soft_snake_gym.cli import main

    code = main([*args, "--out", str(tmp_path / ("x.png" if args[0] == "compare" else "out"))])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and len(err.splitlines()) == 1, err


@pytest.mark.slow
def test_shipped_shared_policy_swims_like_the_decentralized_pid_it_imitated():
    """docs/decentralized.md: within 5 % of DecentralizedPhasePID's speed and 10 % of its cost.

    Seeds 0-2 (not selection seeds). The copy was fitted under backward Euler to the chain
    without the start-up on the clock (``startup=0`` today: a local policy sees no clock); under
    SDIRK2, the default since, it measured 0.1161 against 0.1200 m/s at 1.32 against 1.225.
    """
    from soft_snake_gym.studies.compare import compare

    teacher = "decentralized:startup=0"
    res = compare("SoftEelSegments-v0", ["zoo:ppo", teacher], episodes=3, seed=0)
    agent, base = ({k: v[0] for k, v in res[p].items()} for p in ("zoo:ppo", teacher))  # means
    assert base["average_speed"] > 0.1
    assert agent["average_speed"] > 0.95 * base["average_speed"]
    assert agent["cost_of_transport"] < 1.10 * base["cost_of_transport"]
