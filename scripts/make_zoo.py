"""Train the agents shipped in soft_snake_gym/zoo and write the figures of docs/training.md.

Runs the exact commands recorded in the run folders (the eel and the navigation agents from a
copy of a baseline, the worm fine-tuned with finer integration steps), copies each run's best model (by evaluation return on
its own evaluation seeds, in its last stage) with its VecNormalize statistics and config into
the package, plots the learning curves, and compares the shipped
agents with the baselines on 10 seeds.

    python scripts/make_zoo.py                 # everything (about an hour on 2 cores)
    python scripts/make_zoo.py --skip-training # only copy, plot and compare existing runs
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

from soft_snake_gym.training import plot_learning_curve

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "soft_snake_gym" / "zoo"
DOCS = ROOT / "docs" / "img"

#: env id -> list of soft-snake train argument lists (later ones resume the run)
STAGES = {
    "SoftEel-v0": [
        # a copy of the PID, then gentle PPO at an energy price of 0.005 per W (docs/training.md)
        [
            "--n-timesteps",
            "600000",
            "--hyperparams",
            "imitate=pid",
            "imitate_episodes=16",
            "learning_rate=5e-5",
            "policy_kwargs.log_std_init=-2.5",
            "clip_range=0.1",
            "env_kwargs.energy_cost_weight=0.005",
        ],
    ],
    # the worm's chattering gait lived partly off the step until fine-tuned with 4, then 16
    # internal steps per control step (docs/training.md)
    "SoftWorm-v0": [
        ["--n-timesteps", "1500000"],
        ["--n-timesteps", "1900000", "--hyperparams", "env_kwargs.integrator.substeps=4"],
        ["--n-timesteps", "2150000", "--hyperparams", "env_kwargs.integrator.substeps=16"],
    ],
    # the goal task: a copy of ILOS, then PPO (ppo.yml; docs/navigation.md)
    "SoftEelGoal-v0": [[]],
    "SoftEelPath-v0": [[]],
    # the shared local policy: imitation of the decentralized PID, then PPO, which stopped the eel
    # by the first evaluation at 200k agent-steps; the best model is the imitation (docs/decentralized.md)
    "SoftEelSegments-v0": [
        [
            "--n-timesteps",
            "200000",
            "--hyperparams",
            "imitate=decentralized",
            "imitate_episodes=16",
            "learning_rate=1e-4",
            "policy_kwargs.log_std_init=-2.0",
            "env_kwargs.energy_cost_weight=0.006",
            "eval_freq=200000",
            "checkpoint_freq=200000",
        ],
    ],
}
#: held-out seeds of the navigation comparison (training uses 0..7 and evaluates on 1000..)
NAV_SEED, NAV_EPISODES = "100", "20"


def soft_snake(*args: str) -> None:
    """Run ``soft-snake`` with ``args`` (echoing the command), raising if it fails."""
    cmd = [sys.executable, "-m", "soft_snake_gym.cli", *args]
    print("$", " ".join(["soft-snake", *args]), flush=True)
    subprocess.run(cmd, check=True)


def main() -> None:
    """Train the zoo agents (unless ``--skip-training``), copy their best models into the zoo, compare."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="runs", help="folder of the run folders (default runs/)")
    parser.add_argument("--skip-training", action="store_true", help="use the existing run folders")
    args = parser.parse_args()
    for env_id, stages in STAGES.items():
        run = Path(args.runs) / f"{env_id}_PPO_zoo"
        if not args.skip_training:
            soft_snake("train", env_id, "--run-dir", str(run), "--no-progress", *stages[0])
            for stage in stages[1:]:
                soft_snake("train", "--resume", str(run), "--no-progress", *stage)
        dest = ZOO / env_id / "ppo"
        dest.mkdir(parents=True, exist_ok=True)
        # the best evaluation of the last stage, on the training run's evaluation seeds
        # (1000...); the comparison below uses other seeds (0..9)
        shutil.copy(run / "best_model.zip", dest / "model.zip")
        shutil.copy(run / "best_vecnormalize.pkl", dest / "vecnormalize.pkl")
        for name in ("config.yaml", "command.txt", "meta.json", "learning_curve.csv"):
            shutil.copy(run / name, dest / name)
        plot_learning_curve(run, DOCS / f"learning_curve_{env_id}.png")
    soft_snake(
        "compare",
        "SoftEel-v0",
        "--episodes",
        "10",
        "--out",
        str(DOCS / "compare_SoftEel-v0.png"),
        "--json",
        str(DOCS / "compare_SoftEel-v0.json"),
    )
    soft_snake(
        "compare",
        "SoftWorm-v0",
        "--episodes",
        "10",
        "--out",
        str(DOCS / "compare_SoftWorm-v0.png"),
        "--json",
        str(DOCS / "compare_SoftWorm-v0.json"),
    )
    for env_id in ("SoftEelGoal-v0", "SoftEelPath-v0"):  # docs/navigation.md
        soft_snake(
            "compare",
            env_id,
            "--episodes",
            NAV_EPISODES,
            "--seed",
            NAV_SEED,
            "--out",
            str(DOCS / f"compare_{env_id}.png"),
            "--json",
            str(DOCS / f"compare_{env_id}.json"),
        )


if __name__ == "__main__":
    main()
