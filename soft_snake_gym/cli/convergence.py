"""``soft-snake convergence``: do a policy's episode metrics stay when the integration step shrinks?"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from soft_snake_gym.cli.common import CLIError, add_env_arguments, env_kwargs_from_args
from soft_snake_gym.studies.convergence import DEFAULT_FACTORS, convergence, format_convergence

NAME = "convergence"
HELP = (
    "check that a policy's episode metrics do not change when the "
    "integration step shrinks (exit code 1 if they do)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("env_id", help="environment id, e.g. SoftEel-v0 or SoftWorm-v0")
    p.add_argument(
        "--policy",
        required=True,
        help="what 'evaluate --policy' takes (pid, 'inching:wave=pulse,duty=0.6', zoo:ppo, a run "
        "folder or model zip), or 'random' / 'random:scale=0.5' for a fixed seeded "
        "random-action sequence",
    )
    p.add_argument(
        "--factors",
        type=int,
        nargs="+",
        default=list(DEFAULT_FACTORS),
        metavar="F",
        help="divide the integration step by each (integrator.substeps = k F, the control "
        "step unchanged); the largest is the reference (default 1 4 16)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the episode and of 'random'; the same at every factor (default 0)",
    )
    p.add_argument(
        "--seeds",
        type=int,
        default=1,
        metavar="K",
        help="check K episodes, seeds SEED to SEED+K-1, each at every factor: one seed can pass "
        "by luck (default 1)",
    )
    p.add_argument(
        "--transient",
        type=float,
        default=2.0,
        help="start-up time left out of speed and error [s] (default 2)",
    )
    add_env_arguments(p)
    p.add_argument(
        "--json",
        metavar="PATH",
        help="also write the table as JSON (with --seeds K > 1: every seed's, and the verdict)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the refinement per seed, print each table, write the JSON asked for; 1 if not converged."""
    if args.seeds < 1:
        raise CLIError(f"--seeds {args.seeds} must be at least 1")
    env_kwargs = env_kwargs_from_args(args)
    seeds = range(args.seed, args.seed + args.seeds)
    results = []
    for seed in seeds:  # each table as soon as its seed is done
        results.append(convergence(args.env_id, args.policy, env_kwargs, args.factors, seed, args.transient))
        print(format_convergence(results[-1]), flush=True)
    failed = [seed for seed, r in zip(seeds, results, strict=True) if not r.ok]
    if len(results) > 1:
        line = f"converged on {len(results) - len(failed)} of {len(results)} seeds"
        if failed:
            line += f"; not on seed{'s' * (len(failed) > 1)} {', '.join(map(str, failed))}"
        print(line)
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        data = (
            results[0].to_dict()
            if len(results) == 1
            else {
                "ok": not failed,
                "seeds": list(seeds),
                "results": [r.to_dict() for r in results],
            }
        )
        path.write_text(json.dumps(data, indent=2))
        print(f"wrote {path}")
    return 1 if failed else 0
