"""``soft-snake reproduce``: the sources' headline case, computed by the code and written into the report."""

from __future__ import annotations

import math

import pytest

import soft_snake_gym  # noqa: F401
from soft_snake_gym import Fluid, Rod
from soft_snake_gym.studies.reproduce import HEADLINE_MODELS, headline_case, headline_table, write_report


@pytest.fixture(scope="module")
def short_headline(request):
    """A short headline case with the physics each robot ran on, recorded through the eval env factory.

    One amplitude, 1 s window after a 1.5 s transient.
    """
    import soft_snake_gym.studies.reproduce as reproduce

    seen = []
    make = reproduce.make_eval_env

    def recording(env_id, **kw):
        env = make(env_id, **kw)
        u = env.envs[0].unwrapped
        seen.append((u.sim.config, u.sim.kappa, u.sim.kbar, u.sim.v))
        return env

    mp = pytest.MonkeyPatch()
    mp.setattr(reproduce, "make_eval_env", recording)
    try:
        rows = headline_case(transient_cycles=0.5, cycles=1 / 3, alphas=(math.pi / 3,))
    finally:
        mp.undo()
    return rows, seen


def test_headline_runs_both_controllers_on_both_models_from_rest_on_the_gait(short_headline):
    rows, seen = short_headline
    assert [(r["model"], r["controller"]) for r in rows] == [
        (m, c) for m in HEADLINE_MODELS for c in ("PID (10, 1, 5)", "open loop")
    ]
    from soft_snake_gym.gaits import serpenoid, serpenoid_phase

    kappa_des = serpenoid(serpenoid_phase(0.0, 8, 0.0, math.pi / 4), 0.0, math.pi / 3)[0]
    for row, (config, kappa, kbar, v) in zip(rows, seen, strict=True):
        assert (kappa == pytest.approx(kappa_des, abs=1e-12)) and (kbar == pytest.approx(kappa_des))
        assert not v.any()
        if row["model"] == "thesis preset":
            assert config.rod.damping_bend == config.rod.damping_stretch == 0.0
            assert config.fluid.added_mass == "kelasidi"
        else:  # the package's physics, whatever its defaults
            assert config.rod == Rod() and config.fluid == Fluid()
    for r in rows:
        assert r["failure"] == "" and r["omega"] == pytest.approx(2 * math.pi / 3)
        assert r["speed_cm_s"] > 1.0 and r["fluid_power"] > 0.0  # swims forward, loses power to the water
    for model in HEADLINE_MODELS:  # feedback on the measured curvature tracks the gait better
        pid, ol = (r["curvature_error"] for r in rows if r["model"] == model)
        assert pid < ol


def test_headline_table_goes_into_the_report(short_headline, tmp_path):
    rows, _ = short_headline
    table = headline_table(rows)
    for r in rows:
        assert (
            f"| {r['model']} | {r['controller']} | 1.0472 (pi/3) | {r['speed_cm_s']:.2f} | {r['fluid_power']:.3f} |"
            in table
        )
    extras = {
        "comparison_errors": {"centralized": 0.0, "decentralized": 0.0},
        "sweeps": {},
        "grid": "-",
        "headline": rows,
        "headline_window": "the test window",
    }
    path = write_report(tmp_path / "report.md", tmp_path / "img", [], extras)
    text = path.read_text()
    assert "## The sources' headline case" in text and table in text and "the test window" in text


def test_windowed_fluid_power_is_the_mean_of_the_step_powers():
    from soft_snake_gym.agents import make_policy
    from soft_snake_gym.evaluation import evaluate, make_eval_env

    env = make_eval_env("SoftEel-v0", env_kwargs={"max_episode_steps": 60})
    ep = evaluate(make_policy("open-loop", env), env, episodes=1, transient=0.0)[0]
    assert ep["window_fluid_power"] == pytest.approx(ep["mean_fluid_power"], rel=1e-9)
    ep = evaluate(make_policy("open-loop", env), env, episodes=1, transient=0.2)[0]
    assert ep["window_fluid_power"] != pytest.approx(ep["mean_fluid_power"], rel=1e-3)


def test_com_speed_is_the_displacement_over_the_window_whatever_its_direction():
    import gymnasium as gym
    import numpy as np

    from soft_snake_gym.agents import make_policy
    from soft_snake_gym.evaluation import evaluate, make_eval_env

    kwargs = {"max_episode_steps": 200, "goal_direction": 0.5}
    ep = evaluate(
        make_policy("open-loop", make_eval_env("SoftEel-v0", env_kwargs=kwargs)),
        make_eval_env("SoftEel-v0", env_kwargs=kwargs),
        episodes=1,
        transient=1.0,
    )[0]
    env = gym.make("SoftEel-v0", **kwargs)  # the same episode by hand
    policy = make_policy("open-loop", env)
    obs, _ = env.reset(seed=0)
    state, com = None, {}
    for step in range(1, 201):
        action, state = policy.predict(obs[None], state, np.array([step == 1]))
        obs, *_ = env.step(action[0])
        com[step] = env.unwrapped.sim.com
    assert ep["com_speed"] == pytest.approx(np.linalg.norm(com[200] - com[100]) / 1.0, rel=1e-9)
    # along a goal 0.5 rad off the swimming direction, progress is slower than the speed
    assert ep["average_speed"] < 0.95 * ep["com_speed"]


def test_headline_rejects_bad_arguments():
    with pytest.raises(ValueError, match="cycles = 0 > 0"):
        headline_case(cycles=0)
    with pytest.raises(ValueError, match=r"models \['sources'\] are unknown"):
        headline_case(models=("sources",))
