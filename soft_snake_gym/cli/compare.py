"""``soft-snake compare``: several policies on the same seeds, one table and one bar chart."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from soft_snake_gym.cli.common import CLIError
from soft_snake_gym.studies.compare import (
    DEFAULT_POLICIES,
    check_figure_path,
    compare,
    format_comparison,
    plot_comparison,
)

NAME = "compare"
HELP = "evaluate several policies on the same seeds: one table, one bar chart"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("env_id", nargs="?", default="SoftEel-v0", help="environment id (default SoftEel-v0)")
    p.add_argument(
        "--policies",
        nargs="+",
        metavar="SPEC",
        help="baselines (pid, open-loop, 'pid:alpha=0.6', inching-pid...), run folders, "
        "model zips or zoo:ppo; a seed set (the parent folder of `train --seeds` runs, or a quoted "
        "glob 'runs/x_s*') is reported as the IQM over runs with a 95%% bootstrap CI "
        "(default: the env's baselines and its shipped PPO agent)",
    )
    p.add_argument("--episodes", type=int, default=10, help="episodes per policy (default 10)")
    p.add_argument("--seed", type=int, default=0, help="first seed; every policy gets the same (default 0)")
    p.add_argument("--out", metavar="PNG", help="bar chart path (default compare_<env_id>.png)")
    p.add_argument("--json", metavar="PATH", help="also write the figures as JSON")


def episodes_on_seeds(episodes: int, seed: int) -> str:
    """``1 episode per policy, seed 0`` or ``10 episodes per policy, seeds 0..9``."""
    if episodes == 1:
        return f"1 episode per policy, seed {seed}"
    return f"{episodes} episodes per policy, seeds {seed}..{seed + episodes - 1}"


def run(args: argparse.Namespace) -> int:
    """Compare, print the table, draw the chart, write the JSON asked for."""
    if args.episodes < 1:
        raise CLIError(f"--episodes {args.episodes} must be at least 1")
    try:
        check_figure_path(args.out or f"compare_{args.env_id}.png")
    except ValueError as err:
        raise CLIError(f"--out: {err}") from None
    if args.json and Path(args.json).is_dir():
        raise CLIError(f"--json {args.json!r} is a folder; give a file name")
    specs = args.policies or DEFAULT_POLICIES.get(args.env_id)
    if not specs:
        raise CLIError(
            f"give --policies for {args.env_id} (defaults exist for {', '.join(DEFAULT_POLICIES)})"
        )
    scores: dict = {}
    results = compare(args.env_id, specs, args.episodes, args.seed, scores=scores)
    title = f"{args.env_id}: {episodes_on_seeds(args.episodes, args.seed)}"
    print(format_comparison(results, title))
    out = plot_comparison(results, args.out or f"compare_{args.env_id}.png", title)
    print(f"wrote {out}")
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        clean = {
            s: {k: [x if math.isfinite(x) else None for x in v] for k, v in r.items()}
            for s, r in results.items()
        }
        runs = {
            s: {run: {k: m if math.isfinite(m) else None for k, m in r.items()} for run, r in per_run.items()}
            for s, per_run in scores.items()
        }
        doc = {"env_id": args.env_id, "episodes": args.episodes, "seed": args.seed, "results": clean}
        if runs:  # seed sets: results are [IQM, lower, upper]; each run's mean is here
            doc["seed_sets"] = runs
        path.write_text(json.dumps(doc, indent=2))
        print(f"wrote {path}")
    return 0
