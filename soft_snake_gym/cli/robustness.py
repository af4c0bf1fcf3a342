"""``soft-snake robustness``: learned and classical eel controllers under failures, lost messages, other lengths."""

from __future__ import annotations

import argparse

from soft_snake_gym.cli.common import CLIError, add_env_arguments, env_kwargs_from_args
from soft_snake_gym.studies.robustness import (
    CONTROLLER_KEYS,
    EXPERIMENTS,
    default_controllers,
    format_table,
    run_experiment,
)

NAME = "robustness"
HELP = (
    "shared local policy vs centralized PPO, decentralized and centralized PID: a failed actuator "
    "at each node, lost neighbour messages, other body lengths (a table and a figure each)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument(
        "experiments",
        nargs="*",
        default=list(EXPERIMENTS),
        metavar="EXPERIMENT",
        help=f"any of {', '.join(EXPERIMENTS)} (default: all)",
    )
    p.add_argument("--out", default="robustness", help="folder of the CSVs and figures (default robustness/)")
    p.add_argument(
        "--policy",
        default="zoo:ppo",
        help="the shared local policy on SoftEelSegments-v0: zoo:ppo (default), a run folder or model zip",
    )
    p.add_argument(
        "--controllers",
        nargs="+",
        default=list(CONTROLLER_KEYS),
        help=f"which to compare (default all: {' '.join(CONTROLLER_KEYS)}); cells already in the CSVs are kept",
    )
    p.add_argument("--episodes", type=int, default=3, help="episodes per cell (default 3)")
    p.add_argument(
        "--seed", type=int, default=0, help="first seed, the same for every controller (default 0)"
    )
    p.add_argument(
        "--nodes", type=int, default=10, help="N of the failure and message experiments (default 10)"
    )
    p.add_argument(
        "--fractions",
        type=float,
        nargs="+",
        default=[0.0, 0.1, 0.25, 0.5, 1.0],
        help="fractions of steps with lost messages (default 0 0.1 0.25 0.5 1)",
    )
    p.add_argument(
        "--lengths", type=int, nargs="+", default=[8, 10, 14, 20], help="body lengths N (default 8 10 14 20)"
    )
    p.add_argument("--lost-node", type=int, help="the node whose messages are lost (default N // 2 - 1)")
    add_env_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run the experiments, print a Markdown table of speed and of cost of transport for each."""
    unknown = [e for e in args.experiments if e not in EXPERIMENTS]
    if unknown:
        raise CLIError(f"unknown experiment {unknown[0]!r}; choose from {', '.join(EXPERIMENTS)}")
    controllers = default_controllers(args.policy, tuple(args.controllers))
    for experiment in args.experiments:
        rows = run_experiment(
            experiment,
            args.out,
            controllers,
            episodes=args.episodes,
            seed=args.seed,
            n_nodes=args.nodes,
            fractions=tuple(args.fractions),
            lengths=tuple(args.lengths),
            lost_node=args.lost_node,
            env_kwargs=env_kwargs_from_args(args),
        )
        print(format_table(experiment, rows, "average_speed"))
        print()
        print(format_table(experiment, rows, "cost_of_transport"))
        print(f"wrote {args.out}/{experiment}.csv and {args.out}/{experiment}.png\n")
    return 0
