"""``soft-snake benchmark``.

Steps per second of the envs, the batched env and PPO, against MuJoCo's ``Swimmer-v5``.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path

from soft_snake_gym import plots
from soft_snake_gym.benchmark import (
    DEFAULT_NODES,
    DEFAULT_ROBOTS,
    ENVPOOL_ROBOTS,
    format_report,
    run_benchmark,
)
from soft_snake_gym.cli.common import CLIError
from soft_snake_gym.studies.compare import check_figure_path
from soft_snake_gym.training import sigterm_as_interrupt, stopped_by

NAME = "benchmark"
HELP = "steps per second of the envs, batched env, PPO, against MuJoCo's Swimmer-v5 and EnvPool's Swimmer-v4"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("--seconds", type=float, default=1.0, help="seconds per case per round (default 1)")
    p.add_argument(
        "--repeats", type=int, default=3, help="interleaved rounds; the median is reported (default 3)"
    )
    p.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=list(DEFAULT_ROBOTS),
        help="robot counts of the batched env (default 1 16 256 1024)",
    )
    p.add_argument("--sync-robots", type=int, default=16, help="Swimmer-v5 SyncVectorEnv size (default 16)")
    p.add_argument("--no-ppo", action="store_true", help="skip the PPO training comparison")
    p.add_argument(
        "--ppo-timesteps", type=int, default=8192, help="timed PPO steps per env kind (default 8192)"
    )
    p.add_argument("--ppo-n-envs", type=int, default=None, help="PPO n_envs (default: the PPO config's, 8)")
    p.add_argument(
        "--nodes",
        type=int,
        nargs="*",
        default=list(DEFAULT_NODES),
        help="node counts for the cost-against-N rows (default 10 20 50 100)",
    )
    p.add_argument(
        "--node-robots", type=int, default=64, help="robots in the cost-against-N rows (default 64)"
    )
    p.add_argument(
        "--envpool-robots",
        type=int,
        default=ENVPOOL_ROBOTS,
        help=f"envs of the EnvPool Swimmer-v4 batch row (default {ENVPOOL_ROBOTS})",
    )
    p.add_argument("--json", default="benchmark.json", help="results file (default benchmark.json)")
    p.add_argument("--png", default=None, help="figure (default: the JSON's name with .png)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")


def run(args: argparse.Namespace) -> int:
    """Check the counts, run every case, print the report, write the JSON and the figure."""
    if args.seconds <= 0 or args.repeats < 1:
        raise CLIError(
            f"--seconds {args.seconds} and --repeats {args.repeats}: need seconds > 0 and repeats >= 1"
        )
    bad = [n for n in args.robots + [args.sync_robots, args.node_robots, args.envpool_robots] if n < 1] + [
        N for N in args.nodes if N < 3
    ]
    if bad:
        raise CLIError(f"robot counts must be >= 1 and node counts >= 3; got {bad}")
    if args.ppo_timesteps < 1:
        raise CLIError(f"--ppo-timesteps {args.ppo_timesteps}: need >= 1")
    json_path = Path(args.json)
    if json_path.is_dir():
        raise CLIError(f"--json {args.json!r} is a folder; give a file name for the results")
    png_path = Path(args.png) if args.png else json_path.with_suffix(".png")
    try:  # checked before the run, which would otherwise end in the error with its results lost
        check_figure_path(png_path)
    except ValueError as err:
        raise CLIError(f"--png: {err}") from None

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"[benchmark] {msg}", file=sys.stderr, flush=True)

    try:
        with sigterm_as_interrupt():  # SIGTERM stops the run as Ctrl-C does: what it measured is written
            res = run_benchmark(
                seconds=args.seconds,
                repeats=args.repeats,
                robots=tuple(args.robots),
                sync_robots=args.sync_robots,
                ppo=not args.no_ppo,
                ppo_timesteps=args.ppo_timesteps,
                ppo_n_envs=args.ppo_n_envs,
                nodes=tuple(args.nodes),
                node_robots=args.node_robots,
                envpool_robots=args.envpool_robots,
                progress=progress,
            )
    except KeyboardInterrupt as err:  # before the first round was complete
        sig = stopped_by(err)
        print(
            f"soft-snake benchmark: stopped by {sig.name} before every case had run once; nothing written",
            file=sys.stderr,
        )
        return 128 + sig
    report = format_report(res)
    res["report"] = report
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(res, indent=2))
    png = plots.benchmark_chart(res, png_path)
    print(report)
    print(f"\nwrote {json_path} and {png}")
    stop = res.get("interrupted")
    return 0 if stop is None else 128 + signal.Signals[stop["signal"]]  # as a shell reports the signal
