"""The one key=value grammar and the configs shipped in the package (soft_snake_gym.config)."""

from __future__ import annotations

import math

import gymnasium as gym
import pytest
import yaml

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.cli import main
from soft_snake_gym.config import (
    CONFIG_DIR,
    ConfigError,
    _Loader,
    config_path,
    load_yaml,
    parse_assignments,
    parse_value,
    shipped_configs,
)
from soft_snake_gym.policies import BASELINES, make_baseline


def _old_number_grammar(text: str):
    """The grammar of --env-kwarg and policy options before issue 10 (policies.base.parse_value)."""
    s = text.strip()
    try:
        return int(s) if s.lstrip("+-").isdigit() else float(s)
    except ValueError:
        pass
    value, ok = 1.0, True
    for i, factor in enumerate(s.replace("/", " / ").replace("*", " * ").split()):
        if factor in ("*", "/"):
            op = factor
            continue
        try:
            num = math.pi if factor.lower() == "pi" else float(factor)
        except ValueError:
            ok = False
            break
        value = num if i == 0 else (value * num if op == "*" else value / num)
    return value if ok and s else s


# inputs the old --env-kwarg / policy-option grammar accepted, and what the fields took from them
OLD_EXAMPLES = [
    "0.5",
    "10",
    "-3",
    "+2",
    "1e4",
    "1.875e6",
    "2e-3",
    "pi",
    "pi/6",
    "2*pi/3",
    "-pi/4",
    "PI/2",
    "inf",
    "-inf",
    " 0.25 ",
    "007",
    "pacemaker",
    "circulant",
    "pulse",
    "sine",
    "kelasidi",
    "symplectic_euler",
    "water",
    "none",
    "rgb_array",
]
# inputs of --hyperparams (YAML values) before issue 10
YAML_EXAMPLES = [
    "0.999",
    "3e-4",
    "1.0e-3",
    "512",
    "-1",
    "true",
    "false",
    "null",
    "[128, 128]",
    "[64,64]",
    "{pi: [64, 64], vf: [64, 64]}",
    "tanh",
    "auto",
]


@pytest.mark.parametrize("text", OLD_EXAMPLES)
def test_the_one_grammar_keeps_every_old_number_and_word(text):
    new, old = parse_value(text), _old_number_grammar(text)
    assert new == old or (math.isnan(new) and math.isnan(old))
    assert type(new) is type(old)


@pytest.mark.parametrize("text", YAML_EXAMPLES)
def test_the_one_grammar_keeps_every_yaml_value_of_hyperparams(text):
    old = yaml.load(text, Loader=_Loader)  # noqa: S506 - the package's SafeLoader
    new = parse_value(text)
    assert new == old and type(new) is type(old)


def test_the_grammar_reads_numbers_before_yaml_and_falls_back_to_the_text():
    assert parse_value("pi/6") == math.pi / 6  # YAML alone would give the string 'pi/6'
    assert parse_value("2*pi/3") == 2 * math.pi / 3
    assert parse_value("") is None
    assert parse_value("[1,") == "[1,"  # not YAML: the text, for the receiving field to reject


def test_assignments_nest_dotted_keys_and_name_a_bad_item():
    usage = "--env-kwarg {item} is not key=value; write e.g. --env-kwarg dt=0.02"
    got = parse_assignments(["dt=0.02", "rod.E_bend=1.87e4", "rod.N=12", "goal_direction=[1, 0]"], usage)
    assert got == {"dt": 0.02, "rod": {"E_bend": 1.87e4, "N": 12}, "goal_direction": [1, 0]}
    assert parse_assignments(None, usage) == {}
    with pytest.raises(ConfigError, match=r"^--env-kwarg 'dt0\.02' is not key=value; write e\.g\."):
        parse_assignments(["dt0.02"], usage)
    with pytest.raises(ConfigError, match="'=3' is not key=value"):
        parse_assignments(["=3"], usage)
    flat = parse_assignments(["a.b=1, c=pi ,,"], "{item}", nested=False, sep=",")
    assert flat == {"a.b": 1, "c": math.pi}


def test_shipped_configs_are_found_by_name_and_paths_pass_through(tmp_path):
    assert set(shipped_configs("env")) == {"softeel", "softworm", "eel", "worm"}
    assert set(shipped_configs("policy")) == {
        "pid",
        "pid_soft",
        "open_loop",
        "decentralized",
        "inching",
        "los",
    }
    assert set(shipped_configs("algorithm")) == {"ppo", "sac"}
    assert config_path("softeel", "env") == CONFIG_DIR / "env" / "softeel.yaml"
    assert config_path("pid", "policy") == CONFIG_DIR / "policy" / "pid.yaml"
    for path in ("my.yaml", "cfg/softeel", str(tmp_path / "softeel")):
        assert str(config_path(path, "env")) == path  # a path: load_yaml reports a missing file
    mine = tmp_path / "softeel.yaml"
    assert config_path(mine, "env") == mine
    with pytest.raises(
        ConfigError,
        match=r"env config 'softel' is neither a file nor a config shipped "
        r"with the package \(did you mean 'softeel'\?\); shipped env "
        r"configs: eel, softeel, softworm, worm",
    ):
        config_path("softel", "env")
    with pytest.raises(ValueError, match="config kind 'envs' must be one of env, policy, algorithm"):
        shipped_configs("envs")


@pytest.mark.parametrize("name", ["softeel", "softworm", "eel", "worm"])
def test_every_shipped_env_config_builds_its_env_at_the_defaults(name):
    env_id = "SoftEel-v0" if name in ("softeel", "eel") else "SoftWorm-v0"
    by_name = gym.make(env_id, config=name).unwrapped
    default = gym.make(env_id).unwrapped
    assert by_name.settings == default.settings
    assert by_name.sim.config == default.sim.config


def test_every_shipped_policy_config_builds_a_baseline():
    eel, worm = gym.make("SoftEel-v0"), gym.make("SoftWorm-v0")
    built = {
        "pid": make_baseline("pid", eel, config="pid"),
        "pid_soft": make_baseline("pid", eel, config="pid_soft"),
        "open_loop": make_baseline("open-loop", eel, config="open_loop"),
        "decentralized": make_baseline("decentralized", eel, config="decentralized"),
        "inching": make_baseline("inching-pid", worm, config="inching"),
        "los": make_baseline("los", gym.make("SoftEelPath-v0"), config="los"),
    }
    for name, policy in built.items():
        data = load_yaml(shipped_configs("policy")[name])
        for key, value in data.items():  # every key of the file reached the policy
            assert (
                getattr(policy.params, key) == pytest.approx(value)
                if isinstance(value, float)
                else getattr(policy.params, key) == value
            ), (name, key)
    assert built["pid_soft"].params.Kd == 2.0 and built["pid"].params.Kd == 1.0
    default = make_baseline("los", gym.make("SoftEelGoal-v0")).params  # the file holds the defaults
    for key in ("Kp_heading", "Kd_heading", "gamma_max", "tau", "lookahead", "sigma", "Kp", "Kd", "Ki"):
        assert getattr(built["los"].params, key) == getattr(default, key), key
    assert set(BASELINES) >= {"pid", "open-loop", "decentralized", "inching-pid"}


def test_every_algorithm_config_has_a_section_per_env():
    for path in shipped_configs("algorithm").values():
        assert {"SoftEel-v0", "SoftWorm-v0"} <= set(load_yaml(path))


def test_the_cli_takes_shipped_names_and_lists_them_for_an_unknown_one(capsys):
    code = main(
        [
            "evaluate",
            "SoftEel-v0",
            "--policy",
            "pid",
            "--policy-config",
            "pid_sof",
            "--episodes",
            "1",
            "--max-steps",
            "2",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(
        "soft-snake evaluate: error: policy config 'pid_sof' is neither a file nor a config "
        "shipped with the package (did you mean 'pid_soft'?); shipped policy configs: "
        "decentralized, inching, los, open_loop, pid, pid_soft"
    )
    code = main(
        [
            "evaluate",
            "SoftEel-v0",
            "--policy",
            "pid",
            "--env-config",
            "worm",
            "--episodes",
            "1",
            "--max-steps",
            "2",
        ]
    )
    assert code == 2 and "error: worm sets medium = 'ground'" in capsys.readouterr().err
    code = main(
        [
            "evaluate",
            "SoftEel-v0",
            "--policy",
            "pid",
            "--policy-config",
            "pid_soft",
            "--env-config",
            "softeel",
            "--episodes",
            "1",
            "--max-steps",
            "4",
        ]
    )
    assert code == 0 and "policy=pid" in capsys.readouterr().out
