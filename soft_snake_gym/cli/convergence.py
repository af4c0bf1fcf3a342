"""``soft-snake convergence``: do a policy's episode metrics stay when the integration step shrinks?"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from soft_snake_gym.cli.common import add_env_arguments, env_kwargs_from_args
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
        "--transient",
        type=float,
        default=2.0,
        help="start-up time left out of speed and error [s] (default 2)",
    )
    add_env_arguments(p)
    p.add_argument("--json", metavar="PATH", help="also write the table as JSON")


def run(args: argparse.Namespace) -> int:
    """Run the refinement, print the table, write the JSON asked for; 1 if not converged."""
    env_kwargs = env_kwargs_from_args(args)
    result = convergence(args.env_id, args.policy, env_kwargs, args.factors, args.seed, args.transient)
    print(format_convergence(result))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result.to_dict(), indent=2))
        print(f"wrote {path}")
    return 0 if result.ok else 1
