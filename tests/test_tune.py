"""``soft-snake tune``: real Ray Tune (Optuna TPE + ASHA) on a loopback Ray cluster, then train with its YAML.

The trials are scaled down (384 environment steps, 100-step episodes) but go through the whole
path: the CLI connects with ``--address``, each trial trains in a Ray worker and reports its
evaluations, the best trial's values become a zoo-style YAML that ``soft-snake train`` takes.
"""

from __future__ import annotations

import csv
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support import cli_in_background

from soft_snake_gym.cli import main
from soft_snake_gym.config import ConfigError, load_yaml
from soft_snake_gym.distributed import RAY_INSTALL
from soft_snake_gym.training.tune import SEARCH_SPACE, TuneSettings

TINY = [
    "--trial-steps",
    "384",
    "--evals",
    "3",
    "--search-space",
    "learning_rate,gamma",
    "--hyperparams",
    "n_envs=2",
    "n_steps=64",
    "batch_size=64",
    "n_epochs=2",
    "eval_episodes=1",
    "env_kwargs.max_episode_steps=100",
]


def test_an_unknown_search_space_key_is_one_line_listing_the_valid_keys(capsys, tmp_path):
    code = main(["tune", "--search-space", "learning_rate,lr", "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "unknown search-space key 'lr'" in err and ", ".join(SEARCH_SPACE) in err
    assert not (tmp_path / "t").exists()  # refused before Ray or any folder


def test_an_unreachable_address_is_one_line(capsys, tmp_path):
    pytest.importorskip("ray")
    code = main(["tune", "--trials", "1", "--address", "127.0.0.1:9", "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "no Ray cluster answers there" in err
    assert not (tmp_path / "t").exists()


def test_tune_without_ray_is_one_line_naming_the_install(tmp_path):
    # a Python where `import ray` fails, as without the ray extra
    code = (
        "import sys; sys.modules['ray'] = None; from soft_snake_gym.cli import main; "
        f"sys.exit(main(['tune', '--trials', '1', '--out', {str(tmp_path / 't')!r}]))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "soft-snake tune: error:" in done.stderr and RAY_INSTALL in done.stderr
    assert not (tmp_path / "t").exists()


def test_bad_settings_are_refused_before_ray_starts():
    with pytest.raises(ConfigError, match="trials = 0 must be an integer >= 1"):
        TuneSettings("SoftEel-v0", trials=0)
    with pytest.raises(ConfigError, match="energy_cost_weight changes the reward"):
        TuneSettings("SoftEel-v0", keys=("learning_rate", "energy_cost_weight"))
    with pytest.raises(ConfigError, match="does not exist"):
        TuneSettings("SoftEal-v0")
    with pytest.raises(ConfigError, match="unknown hyperparameter 'gama'"):
        TuneSettings("SoftEel-v0", overrides={"gama": 0.9})


@pytest.fixture(scope="module")
def loopback_cluster(ray_cluster):
    pytest.importorskip("optuna")
    return ray_cluster.address


def _curves(out: Path) -> dict[str, list[dict[str, str]]]:
    """Every trial's learning-curve rows, by trial folder."""
    curves = {}
    for path in sorted(out.glob("*/run/learning_curve.csv")):
        with open(path) as fh:
            curves[path.parent.parent.name] = list(csv.DictReader(fh))
    return curves


@pytest.mark.slow
@pytest.mark.ray
def test_three_trials_resume_after_ctrl_c_and_write_a_yaml_that_train_takes(
    loopback_cluster, tmp_path, capsys
):
    out = tmp_path / "tune"
    args = ["tune", "SoftEel-v0", "--trials", "3", *TINY, "--address", loopback_cluster, "--out", str(out)]

    # Ctrl-C once a trial has evaluated mid-run (and checkpointed): Tune saves its state, exit 130
    proc = cli_in_background(*args, "--quiet")
    deadline = time.time() + 300
    while proc.poll() is None and time.time() < deadline:
        if any(len(rows) >= 2 for rows in _curves(out).values()):
            proc.send_signal(signal.SIGINT)
            break
        time.sleep(0.2)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "run the same command again to resume" in err
    assert not (out / "best.yml").exists()

    # the same command resumes: three trials in all, none trained again from its start
    assert main([*args, "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "resumed; 3 trials scored" in printed
    curves = _curves(out)
    assert len(curves) == 3
    for rows in curves.values():
        steps = [int(r["timesteps"]) for r in rows]
        assert steps == sorted(set(steps)), steps  # a trial restarted from 0 would append 4 again
    finals = [rows[-1] for rows in curves.values()]

    # three draws, scored on the same evaluation seed
    configs = [load_yaml(out / name / "run" / "config.yaml")["SoftEel-v0"] for name in curves]
    assert len({c["learning_rate"] for c in configs}) == 3
    assert all(c["eval_seed"] == 1000 and c["eval_episodes"] == 1 for c in configs)

    # the YAML holds the best finished trial's values over the user's fixed settings, at the
    # config's budget
    section = load_yaml(out / "best.yml")["SoftEel-v0"]
    finished = [
        (float(r["return_mean"]), c)
        for r, c in zip(finals, configs, strict=True)
        if int(r["timesteps"]) >= 384
    ]
    score, winner = max(finished, key=lambda t: t[0])
    assert math.isfinite(score)
    assert section["learning_rate"] == winner["learning_rate"] and section["gamma"] == winner["gamma"]
    assert 1e-5 <= section["learning_rate"] <= 1e-3 and section["gamma"] in SEARCH_SPACE["gamma"].values
    assert section["n_envs"] == 2 and section["n_steps"] == 64
    assert section["env_kwargs"] == {"max_episode_steps": 100}
    assert (
        section["n_timesteps"] == 1_000_000 and section["baseline"] == "default"
    )  # ppo.yml's, not a trial's

    # soft-snake train takes it as is
    run = tmp_path / "run"
    code = main(
        ["train", "SoftEel-v0", "--hyperparams-file", str(out / "best.yml"), "--n-timesteps", "128"]
        + ["--run-dir", str(run), "--no-progress", "--hyperparams", "eval_freq=0", "checkpoint_freq=0"]
    )
    assert code == 0
    trained = load_yaml(run / "config.yaml")["SoftEel-v0"]
    assert trained["learning_rate"] == section["learning_rate"] and trained["gamma"] == section["gamma"]
    assert (run / "final_model.zip").is_file()

    # other settings on the same folder are refused, naming what differs
    capsys.readouterr()
    assert main([*[a if a != "3" else "4" for a in args[:4]], *args[4:], "--quiet"]) == 2
    assert "trials 3 -> 4" in capsys.readouterr().err
