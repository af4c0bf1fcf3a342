"""``soft-snake train``: an SB3 agent (PPO or SAC) with YAML hyperparameters, in a resumable run folder."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from soft_snake_gym.cli.common import CLIError, add_backend_arguments, check_backend_arguments
from soft_snake_gym.config import load_yaml, parse_assignments
from soft_snake_gym.tables import read_rows
from soft_snake_gym.training import (
    ALGOS,
    TrainConfig,
    check_env_id,
    latest_checkpoint,
    load_train_config,
    planned_steps,
    steps_per_iteration,
    stopped_by,
    train,
)
from soft_snake_gym.training.seeds import parse_seeds, train_seeds

NAME = "train"
HELP = "train an SB3 agent (PPO or SAC) with YAML hyperparameters; resumable"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("env_id", nargs="?", default="SoftEel-v0", help="environment id (default SoftEel-v0)")
    p.add_argument("--algo", default="PPO", type=str.upper, choices=ALGOS, help="algorithm (default PPO)")
    p.add_argument(
        "--config",
        "--hyperparams-file",
        dest="config",
        metavar="YAML",
        help="zoo-style hyperparameter file keyed by env id, e.g. soft-snake tune's best.yml (default: "
        "the package's configs/algorithm/<algo>.yml)",
    )
    p.add_argument(
        "--hyperparams",
        nargs="+",
        metavar="KEY=VALUE",
        help="override run settings or hyperparameters, e.g. gamma=0.999 n_envs=4",
    )
    p.add_argument("--n-timesteps", type=int, help="total environment steps (overrides the config)")
    p.add_argument("--seed", type=int, help="seed (overrides the config)")
    p.add_argument(
        "--seeds",
        metavar="RANGE",
        help="train once per seed, e.g. 0-7 or 0,2,5: one run folder per seed, DIR/s<seed> under "
        "--run-dir (default runs/<env>_<algo>)",
    )
    p.add_argument("--run-dir", metavar="DIR", help="run folder (default runs/<env>_<algo>_s<seed>)")
    p.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_backend_arguments(p, "seeds of --seeds (local: one after another)")
    p.add_argument("--workers", type=int, help="with --backend ray and no --address: CPUs of the local Ray")


def _step_plan(cfg: TrainConfig, start: int) -> str:
    """The planned steps as text, and where the checkpoints land.

    For example ``for 4,096 steps (3,000 rounded up to whole rollouts of 512 x 8 steps)``; the
    checkpoints are mentioned when ``n_envs`` does not divide ``checkpoint_freq``.
    """
    end = planned_steps(cfg, start)
    chunk = steps_per_iteration(cfg)
    what = "rollouts of n_steps x n_envs" if cfg.algo == "PPO" else "iterations of train_freq x n_envs"
    text = f"from step {start:,} to {end:,}" if start else f"for {end:,} steps"
    if end != max(cfg.n_timesteps, start):
        text += f" ({cfg.n_timesteps:,} rounded up to whole {what} = {chunk:,} steps)"
    freq = cfg.checkpoint_freq
    if freq and freq % cfg.n_envs:
        text += (
            f"; checkpoints at the first step at or past each multiple of {freq:,} (the {cfg.n_envs} "
            f"envs step together)"
        )
    return text


def run(args: argparse.Namespace) -> int:
    """Train (or resume), then print where the run is and its last evaluation."""
    overrides = parse_assignments(
        args.hyperparams, "--hyperparams {item} is not key=value; write e.g. --hyperparams gamma=0.999"
    )
    for key in ("n_timesteps", "seed"):
        if getattr(args, key) is not None:
            overrides[key] = getattr(args, key)
    if args.seeds is not None:
        return _run_seeds(args, overrides)
    if args.backend != "local" or args.address or args.workers is not None:
        raise CLIError("--backend, --address and --workers spread the seeds of --seeds; add e.g. --seeds 0-3")
    if args.resume:
        run_dir = Path(args.resume)
        if args.run_dir or args.config:
            raise CLIError("--resume continues a run with its own config.yaml; drop --run-dir and --config")
        if not (run_dir / "config.yaml").is_file():
            raise CLIError(f"cannot resume {str(run_dir)!r}: it has no config.yaml (is it a run folder?)")
        saved = load_yaml(run_dir / "config.yaml")
        env_id = next(iter(saved))
        algo = saved[env_id].get("algo", "PPO")
        cfg = load_train_config(env_id, algo, run_dir / "config.yaml", overrides)
    else:
        check_env_id(args.env_id)
        cfg = load_train_config(args.env_id, args.algo, args.config, overrides)
        run_dir = Path(args.run_dir or f"runs/{cfg.env_id}_{cfg.algo}_s{cfg.seed}")
    found = latest_checkpoint(run_dir) if args.resume and run_dir.is_dir() else None
    start = int(found[0].stem.split("_")[1]) if found else 0
    print(
        f"training {cfg.algo} on {cfg.env_id} {_step_plan(cfg, start)} with {cfg.n_envs} envs "
        f"-> {run_dir}" + (" (resumed)" if args.resume else "")
    )
    t0 = time.time()
    try:
        final = train(cfg, run_dir, resume=bool(args.resume), progress=not args.no_progress)
    except KeyboardInterrupt as err:
        sig = stopped_by(err)
        how = "terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted"
        print(
            f"{how}; a checkpoint was saved. Continue with: soft-snake train --resume {run_dir}",
            file=sys.stderr,
        )
        return 128 + sig
    wall = time.time() - t0
    print(f"done in {wall:.0f} s; final model {final}")
    rows = read_rows(run_dir / "learning_curve.csv")
    if rows:
        last = rows[-1]
        line = (
            f"last evaluation at {last['timesteps']} steps: return {float(last['return_mean']):.4g}, "
            f"average speed {float(last['average_speed_mean']):.4g} m/s"
        )
        if "baseline_return" in last:
            line += (
                f" (baseline {cfg.baseline_spec}: return {float(last['baseline_return']):.4g}, "
                f"average speed {float(last['baseline_average_speed']):.4g} m/s)"
            )
        print(line)
    print(f"evaluate it with: soft-snake evaluate {cfg.env_id} --policy {run_dir}")
    return 0


def _run_seeds(args: argparse.Namespace, overrides: dict) -> int:
    """``--seeds``: one run folder per seed, here or on Ray."""
    seeds = parse_seeds(args.seeds)
    if args.seed is not None or args.resume:
        raise CLIError("--seeds trains new runs of its own seeds; drop --seed and --resume")
    if args.workers is not None and args.workers < 1:
        raise CLIError(f"--workers {args.workers} must be at least 1")
    check_backend_arguments(args)
    check_env_id(args.env_id)
    cfg = load_train_config(args.env_id, args.algo, args.config, overrides)
    parent = Path(args.run_dir or f"runs/{cfg.env_id}_{cfg.algo}")
    where = "one after another" if args.backend == "local" else f"on Ray ({args.address or 'local'})"
    print(
        f"training {cfg.algo} on {cfg.env_id} {_step_plan(cfg, 0)} with {cfg.n_envs} envs, "
        f"seeds {args.seeds} ({len(seeds)} runs, {where}) -> {parent}/s<seed>"
    )
    t0 = time.time()

    def done(seed: int, final: Path) -> None:
        print(f"seed {seed} done after {time.time() - t0:.0f} s: {final}")

    try:
        train_seeds(
            cfg,
            seeds,
            parent,
            backend=args.backend,
            address=args.address,
            workers=args.workers,
            progress=not args.no_progress,
            on_done=done,
        )
    except KeyboardInterrupt:
        print(
            "interrupted; each seed's folder keeps its checkpoints: continue one with "
            f"soft-snake train --resume {parent}/s<seed>",
            file=sys.stderr,
        )
        return 130
    print(
        f"done in {time.time() - t0:.0f} s; compare them with: soft-snake compare {cfg.env_id} --policies {parent}"
    )
    return 0
