"""Convergence in the time step (docs/model.md §5a, §10).

Every baseline, the shipped agents and a fixed seeded random-action sequence give the same episode
metrics at the default integration step and with it divided by 4 and 16 (5 % in water, 10 % on the
ground), the same for random actions under the optional BDF2 integrator, and the
``soft-snake convergence`` command that prints the table.

The cases in :data:`KNOWN_FAILING` do not converge yet, each with the measured reason; they
are strict ``xfail``: the day one converges, the suite says so and its entry must be removed.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from gymnasium.spaces import Box

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.cli import main
from soft_snake_gym.config import ConfigError
from soft_snake_gym.studies.convergence import (
    ABSOLUTE_TOLERANCE,
    ConvergenceResult,
    RandomActions,
    convergence,
    format_convergence,
)

EEL = [
    "open-loop",
    "pid",  # gains (10, 1, 5)
    "pid:Kd=2,Ki=1",  # gains (10, 2, 1)
    "decentralized",  # circulant closure, 2 s on the clock first
    "decentralized:closure=pacemaker",
    "zoo:ppo",
    "random",
]
WORM = [
    "inching",  # the peristaltic pulse, the default wave
    "inching-pid",
    "inching:wave=sine",
    "inching-pid:wave=sine",
    "zoo:ppo",
    "random",
]
CASES = [("SoftEel-v0", s) for s in EEL] + [("SoftWorm-v0", s) for s in WORM]
#: the circulant chain from the first step (no start-up), as the sources run it from rest on the gait
BARE_CHAIN = "decentralized:startup=0"
ON_GAIT = {"start_on_gait": {}}
#: the cheaper second-order method, under the load that needs the most Newton iterations
BDF2 = {"integrator": {"method": "bdf2"}}

#: (env, policy) -> what does not converge today (measured at factors 1, 4, 16, seed 0; the
#: ratios are value / value at h/16, for h = 0.01 s, h/4, h/16).
KNOWN_FAILING = {
    ("SoftEel-v0", BARE_CHAIN): "curvature error 0.0247, 0.0431, 0.0380 (35 %; speed and fluid "
    "power within 3.9 %). From the straight, still start there is no phase to estimate: each node's "
    "atan2(phi, phi_dot / omega) reads the start's small vibrations, and the chain amplifies any "
    "difference in them: the start's noise scaled by 1 + 1e-4 moves the error at h from 0.0247 to "
    "0.0377, as much as the step does. The ring's slow mode (the errors of the neighbours' phase "
    "lags rotating around it, period about 10.5 s) carries that difference through the episode. Over seeds 0-23 the errors differ "
    "between the steps by up to 3.7x, and 4 seeds never start a wave at any step (all nodes bent "
    "one way, the integral cancelling the feed-forward; seed 4 too at h/4). The default start-up "
    "on the clock (the case 'decentralized' above) converges on all 24 seeds within 2.1 %, and "
    "so does this chain from rest on the gait (the case below)",
}


def _case(env_id: str, spec: str, env_kwargs: dict | None = None, label: str = ""):
    reason = None if env_kwargs else KNOWN_FAILING.get((env_id, spec))
    marks = [pytest.mark.xfail(reason=reason, strict=True, raises=AssertionError)] if reason else []
    return pytest.param(env_id, spec, env_kwargs, marks=marks, id=f"{env_id}-{spec}{label}")


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize(
    ("env_id", "spec", "env_kwargs"),
    [_case(*c) for c in CASES]
    + [
        _case("SoftEel-v0", BARE_CHAIN),
        _case("SoftEel-v0", BARE_CHAIN, ON_GAIT, "-on-gait"),
        _case("SoftEel-v0", "random", BDF2, "-bdf2"),
    ],
)
def test_episode_metrics_do_not_depend_on_the_time_step(env_id, spec, env_kwargs):
    result = convergence(env_id, spec, env_kwargs=env_kwargs, factors=(1, 4, 16), seed=0)
    assert result.substeps == [1, 4, 16]
    assert not any(result.failures), format_convergence(result)
    checked = [m for m in result.values if result.passed(m) is not None]
    # every metric but the tracking error (which a trained agent or random actions lack) is defined
    assert len(checked) >= 3
    assert result.ok, "\n" + format_convergence(result)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
@pytest.mark.parametrize("spec", ["decentralized", "decentralized:closure=pacemaker"])
def test_the_decentralized_chains_converge_from_other_starts_too(spec, seed):
    # seed 0 alone proved little: without the start-up on the clock, over seeds 0-23 the circulant
    # chain failed on 20 (4 never swam) and the pacemaker chain on 9 (its errors 16 % apart)
    result = convergence("SoftEel-v0", spec, factors=(1, 4, 16), seed=seed)
    assert result.values["average_speed"][-1] > 0.12  # a wave, not a stall
    assert result.ok, "\n" + format_convergence(result)


def _result(values: dict[str, list[float]], medium: str = "water", failures=None) -> ConvergenceResult:
    n = len(next(iter(values.values())))
    return ConvergenceResult(
        env_id="X",
        policy="p",
        medium=medium,
        method="sdirk2",
        factors=[4**i for i in range(n)],
        substeps=[4**i for i in range(n)],
        h=[0.01 / 4**i for i in range(n)],
        values=values,
        failures=failures or [""] * n,
        rtol={"water": 0.05, "ground": 0.10}[medium],
        atol={m: ABSOLUTE_TOLERANCE[m] for m in values},
    )


def test_the_decision_rule_is_relative_to_the_finest_run_with_an_absolute_floor():
    r = _result({"average_speed": [0.104, 0.101, 0.1], "energy_actuator": [62.9, 61.0, 60.0]})
    assert r.passed("average_speed") and r.passed("energy_actuator") and r.ok  # 4 %, 4.8 %
    r = _result({"average_speed": [0.106, 0.1, 0.1]})
    assert r.passed("average_speed") is False and not r.ok  # 6 % > 5 % in water
    assert _result({"average_speed": [0.106, 0.1, 0.1]}, medium="ground").passed("average_speed")  # 10 %
    # near zero the absolute tolerance decides: 0.9 mm/s off a speed of 0.1 mm/s passes, 1.1 does not
    assert _result({"average_speed": [0.0010, 0.0001, 0.0001]}).passed("average_speed")
    assert not _result({"average_speed": [0.0012, 0.0001, 0.0001]}).passed("average_speed")
    # a metric no run defines is not checked; a failed episode fails everything
    r = _result({"average_speed": [0.1, 0.1, 0.1], "curvature_error": [math.nan] * 3})
    assert r.passed("curvature_error") is None and r.ok
    r = _result({"average_speed": [0.1, 0.1, 0.1]}, failures=["", "self_intersection", ""])
    assert r.passed("average_speed") is False and not r.ok


def test_random_actions_are_one_fixed_sequence_per_seed():
    space = Box(-1.0, 1.0, (9,), np.float32)
    obs = np.zeros((1, 5))
    a, b = RandomActions(space, seed=3, scale=0.5), RandomActions(space, seed=3, scale=0.5)
    first = [a.predict(obs, None, np.array([i == 0]))[0] for i in range(20)]
    again = [a.predict(obs, None, np.array([i == 0]))[0] for i in range(20)]  # a new episode restarts it
    other = [b.predict(obs, None, np.array([i == 0]))[0] for i in range(20)]
    assert np.array_equal(first, again) and np.array_equal(first, other)
    assert first[0].shape == (1, 9) and np.abs(first).max() <= 0.5 and np.abs(first).max() > 0.4
    assert not np.array_equal(first[0], first[1])
    c = RandomActions(space, seed=4)
    assert not np.array_equal(first[0], c.predict(obs, None, np.array([True]))[0])
    for bad in (0.0, 1.5, -1.0, True):
        with pytest.raises(ValueError, match="scale"):
            RandomActions(space, scale=bad)


def test_bad_factors_and_policies_are_rejected_before_any_episode():
    for factors, match in (
        ((1,), "at least two"),
        ((0, 4), "at least two"),
        ((4, 4), "repeat"),
        ((1, 2.5), "integers"),
    ):
        with pytest.raises(ConfigError, match=match):
            convergence("SoftWorm-v0", "inching", factors=factors)
    with pytest.raises(ConfigError, match="unknown key 'scal'"):
        convergence("SoftWorm-v0", "random:scal=0.5")
    with pytest.raises(ConfigError, match="scale = 2"):
        convergence("SoftWorm-v0", "random:scale=2")


def test_refinement_multiplies_the_configured_substeps_and_changes_the_step():
    # two internal steps in the user's config: the refinements take 2 * factor
    r = convergence(
        "SoftEel-v0",
        "pid",
        env_kwargs={"integrator": {"substeps": 2}, "max_episode_steps": 150},
        factors=(1, 4),
        transient=0.5,
    )
    assert r.substeps == [2, 8] and r.h == pytest.approx([0.005, 0.00125])
    # the runs really differ in their step: the closed loop's curvature error changes with it
    err = r.values["curvature_error"]
    assert err[0] != err[1] and all(np.isfinite(err))


def test_cli_prints_the_table_writes_json_and_exit_code_says_converged(capsys, tmp_path):
    path = tmp_path / "c.json"
    code = main(
        [
            "convergence",
            "SoftWorm-v0",
            "--policy",
            "inching-pid:wave=pulse",
            "--factors",
            "1",
            "4",
            "--max-steps",
            "200",
            "--transient",
            "0.5",
            "--json",
            str(path),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    for label in ("distance", "friction energy", "actuator energy", "length error", "PASS", "converged"):
        assert label in out
    assert "0.0025 s (backward_euler)" in out  # the ground's integrator, named
    data = json.loads(path.read_text())
    assert data["ok"] and data["substeps"] == [1, 4] and data["method"] == "backward_euler"
    dist = data["metrics"]["distance"]["values"]
    assert f"{dist[0]:.4g}" in out and dist[0] > 0
    # the thesis preset (no damping) leaves the PID's closed loop to the step: exit code 1, FAIL
    code = main(
        [
            "convergence",
            "SoftEel-v0",
            "--policy",
            "pid",
            "--env-kwarg",
            "preset=thesis",
            "--factors",
            "1",
            "16",
            "--max-steps",
            "200",
            "--transient",
            "0.5",
        ]
    )
    out = capsys.readouterr().out
    assert code == 1 and "FAIL" in out and "NOT converged" in out
    assert "s (backward_euler);" in out  # the preset's integrator, not the default's
    code = main(["convergence", "SoftWorm-v0", "--policy", "inching:wave=sine,duty=0.5"])
    assert code == 2 and "duty" in capsys.readouterr().err


def test_cli_checks_several_seeds_and_names_those_that_do_not_converge(capsys, tmp_path):
    # the bare circulant chain (no start-up) from its noisy start: seed 10 does not converge
    # (curvature error 0.0441, 0.0354, 0.0139 at h, h/4, h/16), seed 11 does
    path = tmp_path / "seeds.json"
    args = ["convergence", "SoftEel-v0", "--policy", "decentralized:startup=0", "--seed", "10"]
    code = main([*args, "--seeds", "2", "--json", str(path)])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "one episode (seed 10)" in out and "one episode (seed 11)" in out
    assert "converged on 1 of 2 seeds; not on seed 10" in out
    data = json.loads(path.read_text())
    assert data["ok"] is False and data["seeds"] == [10, 11]
    assert [r["seed"] for r in data["results"]] == [10, 11]
    assert [r["ok"] for r in data["results"]] == [False, True]
    assert main([*args, "--seeds", "0"]) == 2
    assert "--seeds 0 must be at least 1" in capsys.readouterr().err
