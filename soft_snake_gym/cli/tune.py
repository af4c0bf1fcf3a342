"""``soft-snake tune``: PPO's hyperparameters by Ray Tune (Optuna TPE + ASHA); writes a zoo-style YAML."""

from __future__ import annotations

import argparse
import sys
import time

from soft_snake_gym.cli.common import CLIError
from soft_snake_gym.config import parse_assignments
from soft_snake_gym.distributed import connected
from soft_snake_gym.training.tune import METRIC_MODES, SEARCH_SPACE, TuneInterrupted, TuneSettings, tune_ppo

NAME = "tune"
HELP = "tune PPO's hyperparameters on Ray Tune (Optuna TPE + ASHA); writes a YAML for train"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    space = "; ".join(f"{k}: {v.describe()}" for k, v in SEARCH_SPACE.items())
    p.add_argument("env_id", nargs="?", default="SoftEel-v0", help="environment id (default SoftEel-v0)")
    p.add_argument("--trials", type=int, default=20, help="trials (hyperparameter draws; default 20)")
    p.add_argument(
        "--trial-steps",
        type=int,
        default=100_000,
        help="environment steps of a trial that ASHA does not stop (default 100000)",
    )
    p.add_argument("--evals", type=int, default=4, help="evaluations (reports to ASHA) per trial (default 4)")
    p.add_argument(
        "--search-space",
        metavar="KEY,...",
        help=f"keys to tune (default: all but energy_cost_weight). {space}",
    )
    p.add_argument(
        "--metric",
        default="return",
        choices=list(METRIC_MODES),
        help="the evaluation metric scored (default return; cost_of_transport is minimized)",
    )
    p.add_argument(
        "--config",
        "--hyperparams-file",
        dest="config",
        metavar="YAML",
        help="zoo-style hyperparameter file to start from (default: the package's ppo.yml)",
    )
    p.add_argument(
        "--hyperparams",
        nargs="+",
        metavar="KEY=VALUE",
        help="fixed run settings or hyperparameters for every trial, e.g. n_envs=4 n_epochs=5",
    )
    p.add_argument("--address", help="Ray cluster address (host:port or auto; default: a local Ray)")
    p.add_argument(
        "--cpus-per-trial", type=int, default=1, help="Ray CPUs per trial, its threads' cap (default 1)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the TPE sampler (default 0)")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="experiment folder (default tune/<env>); an interrupted run in it resumes",
    )
    p.add_argument("--quiet", action="store_true", help="no Tune status table")


def run(args: argparse.Namespace) -> int:
    """Check everything, connect to Ray, tune, and print the best trial and the YAML written."""
    overrides = parse_assignments(
        args.hyperparams, "--hyperparams {item} is not key=value; write e.g. --hyperparams n_envs=4"
    )
    keys = tuple(k.strip() for k in args.search_space.split(",") if k.strip()) if args.search_space else None
    if args.search_space is not None and not keys:
        raise CLIError(f"--search-space is empty; give keys from: {', '.join(SEARCH_SPACE)}")
    settings = TuneSettings(
        env_id=args.env_id,
        trials=args.trials,
        trial_steps=args.trial_steps,
        evals=args.evals,
        metric=args.metric,
        config=args.config,
        overrides=overrides,
        seed=args.seed,
        cpus_per_trial=args.cpus_per_trial,
        **({"keys": keys} if keys else {}),
    )
    out = args.out or f"tune/{settings.env_id}"
    t0 = time.time()
    try:
        with connected(args.address, task_cpus=settings.cpus_per_trial):
            result = tune_ppo(settings, out, verbose=0 if args.quiet else 1)
    except TuneInterrupted as err:
        print(f"interrupted ({err}); run the same command again to resume {out}", file=sys.stderr)
        return 130
    wall = time.time() - t0
    print(
        f"{'resumed; ' if result.resumed else ''}{len(result.trials)} trials scored"
        f"{f', {result.errors} failed' if result.errors else ''} in {wall:.0f} s"
    )
    ranked = sorted(result.trials, key=lambda t: t[1], reverse=METRIC_MODES[settings.metric] == "max")
    keys = list(settings.keys)
    width = max(12, *(len(k) + 2 for k in keys))
    print(f"{settings.metric:>14} {'steps':>9} " + "".join(f"{k:>{width}}" for k in keys))
    for params, score, steps in ranked:
        print(f"{score:>14.5g} {steps:>9,} " + "".join(f"{params[k]:>{width}.4g}" for k in keys))
    print(f"best: {settings.metric} {result.best_score:.5g} after {result.best_steps:,} steps")
    print(f"wrote {result.yaml_path}")
    print(f"train with: soft-snake train {settings.env_id} --hyperparams-file {result.yaml_path}")
    return 0
