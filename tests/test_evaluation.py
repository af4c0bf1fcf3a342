"""The metric registry of soft_snake_gym.evaluation: one name, label, unit and window per metric."""

from __future__ import annotations

import math

import pytest
from stable_baselines3.common.evaluation import evaluate_policy

from soft_snake_gym.agents import make_policy
from soft_snake_gym.evaluation import COLUMNS, METRICS, TABLE, evaluate, make_eval_env


def test_every_number_an_episode_reports_is_in_the_registry_under_its_meaning():
    env = make_eval_env("SoftEel-v0", seed=0, env_kwargs={"max_episode_steps": 300})
    seen = {}

    def keep_last_info(locals_, globals_):
        seen["info"] = locals_["info"]

    (episode,) = evaluate(make_policy("pid", env), env, episodes=1, transient=1.0)
    bookkeeping = {"steps", "window_start", "failure"}
    keys = {m.key for m in METRICS.values() if m.source == "evaluation"}
    assert set(episode) - bookkeeping <= keys
    # the two speeds under one key: evaluation's is the forward speed after the transient, the
    # env's (registry name episode_speed) is distance / duration over the whole episode
    assert METRICS["average_speed"].window == "transient" and METRICS["episode_speed"].window == "episode"
    assert METRICS["episode_speed"].key == "average_speed" and METRICS["episode_speed"].source == "env"
    env.seed(0)
    evaluate_policy(make_policy("pid", env), env, n_eval_episodes=1, callback=keep_last_info, warn=False)
    whole = seen["info"]["metrics"]["average_speed"]
    assert whole == pytest.approx(episode["distance"] / episode["duration"], rel=1e-12)
    assert not math.isclose(whole, episode["average_speed"], rel_tol=1e-3)  # the start-up is slower


def test_the_table_columns_come_from_the_registry():
    assert [key for key, _, _ in COLUMNS] == list(TABLE)
    assert ("mean_fluid_power", "fluid power", "W") in COLUMNS
    assert all(m.window in ("transient", "episode") and m.unit for m in METRICS.values())
