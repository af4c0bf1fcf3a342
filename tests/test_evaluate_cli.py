"""``soft-snake evaluate``: tables, JSON, video, trained models, and one-line errors."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import gymnasium as gym
import pytest

import soft_snake_gym  # noqa: F401
from soft_snake_gym.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_evaluate_prints_the_table_and_writes_json(capsys, tmp_path):
    path = tmp_path / "pid.json"
    code, out, err = run(
        capsys,
        "evaluate",
        "SoftEel-v0",
        "--policy",
        "pid:alpha=0.5,omega=2.1",
        "--episodes",
        "2",
        "--max-steps",
        "150",
        "--transient",
        "0.5",
        "--json",
        str(path),
    )
    assert code == 0, err
    for label in ("return", "average speed", "curvature error", "fluid power", "cost of transport"):
        assert label in out
    data = json.loads(path.read_text())
    assert len(data["episodes"]) == 2 and data["episodes"][0]["steps"] == 150
    mean = data["summary"]["average_speed"]["mean"]
    assert f"{mean:.4g}" in out  # the table shows the figures in the file
    assert mean > 0  # swims forward


def test_evaluate_worm_table(capsys):
    code, out, err = run(
        capsys,
        "evaluate",
        "SoftWorm-v0",
        "--policy",
        "inching-pid",
        "--episodes",
        "1",
        "--max-steps",
        "200",
        "--transient",
        "0.5",
    )
    assert code == 0, err
    assert "length error" in out and "friction energy" in out and "curvature error" not in out


def test_evaluate_records_a_video(capsys, tmp_path):
    path = tmp_path / "eel.gif"
    code, out, err = run(
        capsys,
        "evaluate",
        "SoftEel-v0",
        "--policy",
        "open-loop",
        "--episodes",
        "1",
        "--max-steps",
        "12",
        "--video",
        str(path),
    )
    assert code == 0, err
    from PIL import Image

    with Image.open(path) as im:
        assert im.n_frames >= 3  # the reset frame plus one every 4 steps


def test_evaluate_a_trained_model_and_reject_it_on_the_other_env(capsys, tmp_path):
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", gym.make("SoftEel-v0"), n_steps=64, batch_size=64, seed=0)
    model.save(tmp_path / "eel_ppo")
    code, out, err = run(
        capsys,
        "evaluate",
        "SoftEel-v0",
        "--policy",
        str(tmp_path / "eel_ppo.zip"),
        "--episodes",
        "1",
        "--max-steps",
        "20",
    )
    assert code == 0, err
    assert "curvature error" in out and "n/a" in out  # a model has no reference gait
    code, out, err = run(
        capsys,
        "evaluate",
        "SoftWorm-v0",
        "--policy",
        str(tmp_path / "eel_ppo.zip"),
        "--episodes",
        "1",
        "--max-steps",
        "20",
    )
    assert code == 2 and "trained on observations" in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["SoftEel-v0", "--policy", "pidd"], "unknown policy 'pidd'; did you mean 'pid'?"),
        (["SoftEel-v0", "--policy", "pid:alpah=0.5"], "unknown key 'alpah'"),
        (["SoftEel-v0", "--policy", "pid:alpha"], "is not key=value"),
        (["SoftWorm-v0", "--policy", "pid"], "use 'inching' or 'inching-pid' on SoftWorm-v0"),
        (["SoftEel-v0", "--policy", "inching-pid"], "on SoftEel-v0"),
        (["SoftEel-v0", "--policy", "models/missing.zip"], "'models/missing.zip' does not exist"),
        (["SoftEel-v0", "--policy", "pid", "--episodes", "0"], "must be at least 1"),
        (["SoftEel-v0", "--policy", "pid", "--video", "x.avi"], "must end in .mp4 or .gif"),
        (
            ["SoftEel-v0", "--policy", "inching", "--start-on-gait"],
            "policy 'inching' has no serpenoid gait to start on",
        ),
        (["SoftEel-v0", "--policy", "zoo:ppo", "--start-on-gait"], "--env-kwarg start_on_gait.alpha"),
        (
            ["SoftEel-v0", "--policy", "pid", "--start-on-gait", "--env-kwarg", "start_on_gait.alpha=1"],
            "drop --env-kwarg start_on_gait",
        ),
        (
            ["SoftEel-v0", "--policy", "pid:alpha=-1", "--start-on-gait"],
            "alpha = -1.0 rad must be in [0, pi)",
        ),
        (["SoftEel-v0", "--policy", "pid", "--env-kwarg", "preset=nope"], "preset = 'nope' is unknown"),
    ],
)
def test_bad_options_are_one_line_errors(capsys, argv, message):
    code, out, err = run(capsys, "evaluate", *argv)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_installed_console_script_errors_without_traceback():
    exe = shutil.which("soft-snake") or str(__import__("pathlib").Path(sys.executable).parent / "soft-snake")
    proc = subprocess.run(
        [exe, "evaluate", "SoftWorm-v0", "--policy", "pid"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("soft-snake evaluate: error: policy 'pid' controls curvature")
    assert len(proc.stderr.strip().splitlines()) == 1


def test_every_command_is_a_module_of_the_cli_package():
    from soft_snake_gym.cli import build_parser, commands

    names = set(commands())
    assert "evaluate" in names
    help_text = build_parser().format_help()
    assert all(name in help_text for name in names)


def test_evaluate_start_on_gait_takes_the_gait_from_the_policy(capsys, tmp_path):
    """From rest on the policy's gait the PID's curvature error at t = 0 is zero.

    From the straight start it is the gait's own size (|kappa_des| up to 2 tan(pi/6) = 1.15).
    """
    errors = {}
    for start in (True, False):
        path = tmp_path / f"{start}.json"
        argv = [
            "evaluate",
            "SoftEel-v0",
            "--policy",
            "pid:alpha=pi/3,psi0=0.5",
            "--episodes",
            "1",
            "--max-steps",
            "1",
            "--transient",
            "0",
            "--json",
            str(path),
        ]
        code, out, err = run(capsys, *argv, *(["--start-on-gait"] if start else []))
        assert code == 0, err
        errors[start] = json.loads(path.read_text())["episodes"][0]["curvature_error"]
    assert errors[True] < 1e-6 and errors[False] > 0.3


def test_policy_gait_reads_the_spec_and_the_policy_config():
    import math

    from soft_snake_gym.config import ConfigError
    from soft_snake_gym.policies import policy_gait

    gait = policy_gait("pid:alpha=pi/3", config="pid")  # the shipped policy config, by name
    assert gait == {
        "alpha": math.pi / 3,
        "omega": 2 * math.pi / 3,
        "delta": math.pi / 4,
        "gamma": 0.0,
        "psi0": 0.0,
    }
    assert policy_gait("decentralized:omega=3,closure=pacemaker")["omega"] == 3.0
    assert policy_gait("open-loop")["delta"] is None  # the env resolves 2 pi / (N - 2)
    with pytest.raises(ConfigError, match="unknown key 'alph'"):
        policy_gait("open-loop:alph=1")


def test_a_video_does_not_change_the_evaluated_episode(tmp_path):
    from soft_snake_gym.agents import make_policy
    from soft_snake_gym.evaluation import evaluate, make_eval_env

    def episode(video):
        env = make_eval_env(
            "SoftEelGoal-v0", seed=7, env_kwargs={"max_episode_steps": 60}, render_mode="rgb_array"
        )
        return evaluate(make_policy("los", env), env, episodes=1, transient=0.1, video=video)[0]

    path = tmp_path / "goal.gif"
    with_video, without = episode(path), episode(None)
    assert with_video == without  # the seeded target and start, as without a video
    assert path.stat().st_size > 0
