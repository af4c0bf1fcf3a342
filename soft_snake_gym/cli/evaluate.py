"""``soft-snake evaluate``: a baseline or a trained model for K episodes, one table."""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from soft_snake_gym.agents import make_policy
from soft_snake_gym.cli.common import CLIError, add_env_arguments, env_kwargs_from_args
from soft_snake_gym.evaluation import (
    check_transient,
    check_video_path,
    evaluate,
    format_table,
    make_eval_env,
    summarize,
)
from soft_snake_gym.policies import policy_gait

NAME = "evaluate"
HELP = "evaluate a baseline or a trained model for K episodes"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("env_id", help="environment id, e.g. SoftEel-v0 or SoftWorm-v0")
    p.add_argument(
        "--policy",
        required=True,
        help="baseline name with options (pid, 'pid:alpha=0.5,omega=2.1', decentralized, "
        "'decentralized:closure=pacemaker', open-loop, inching, inching-pid) "
        "or the path to a saved SB3 model (.zip)",
    )
    p.add_argument(
        "--policy-config",
        metavar="YAML",
        help="YAML file of the policy's gait/gains, or a shipped one by name (pid, pid_soft, "
        "open_loop, decentralized, inching)",
    )
    p.add_argument("--episodes", type=int, default=3, help="number of episodes (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument(
        "--transient",
        type=float,
        help="start-up time left out of speed and error [s] (default 2, or half the "
        "episode if that is shorter)",
    )
    add_env_arguments(p)
    p.add_argument(
        "--start-on-gait",
        action="store_true",
        help="start at rest on the policy's own serpenoid gait (curvatures = desired at t = 0, "
        "no start noise): the env keyword start_on_gait, for open-loop, pid, decentralized",
    )
    p.add_argument("--json", metavar="PATH", help="also write the per-episode metrics and summary")
    p.add_argument("--video", metavar="PATH", help="record the first episode (.mp4 or .gif)")


def run(args: argparse.Namespace) -> int:
    """Evaluate, print the table, write the JSON and video asked for."""
    if args.episodes < 1:
        raise CLIError(f"--episodes {args.episodes} must be at least 1")
    if args.transient is not None and not (math.isfinite(args.transient) and args.transient >= 0):
        raise CLIError(f"--transient {args.transient:g} must be a number of seconds >= 0")
    if args.video:
        try:
            check_video_path(args.video)
        except ValueError as err:
            raise CLIError(f"--video: {err}") from None
    env_kwargs = env_kwargs_from_args(args)
    if args.start_on_gait:
        if "start_on_gait" in env_kwargs:
            raise CLIError(
                "--start-on-gait takes the gait from the policy; drop --env-kwarg start_on_gait..."
            )
        env_kwargs["start_on_gait"] = policy_gait(args.policy, args.policy_config)
    env = make_eval_env(
        args.env_id, seed=args.seed, env_kwargs=env_kwargs, render_mode="rgb_array" if args.video else None
    )
    inner = env.envs[0]
    limit = inner.spec.max_episode_steps if inner.spec is not None else None
    duration = limit * inner.unwrapped.dt if limit else math.inf
    if args.transient is None:
        args.transient = min(2.0, duration / 2)
    try:
        check_transient(args.transient, duration)
    except ValueError as err:
        raise CLIError(f"--transient: {err}") from None
    policy = make_policy(args.policy, env, config=args.policy_config)
    t0 = time.perf_counter()
    episodes = evaluate(policy, env, episodes=args.episodes, transient=args.transient, video=args.video)
    elapsed = time.perf_counter() - t0
    summary = summarize(episodes)
    whole = sum(e["window_start"] != args.transient for e in episodes)
    window = f"metrics after a {args.transient:g} s transient"
    if whole:
        window += (
            f" (over the whole episode for {whole} of {len(episodes)} that ended before "
            f"{2 * args.transient:g} s)"
        )
    durations = sorted({round(e["duration"], 1) for e in episodes})
    each = (
        f"{durations[0]:.1f} s each" if len(durations) == 1 else f"{durations[0]:.1f}-{durations[-1]:.1f} s"
    )
    title = (
        f"{args.env_id}  policy={args.policy}  episodes={args.episodes}  "
        f"({each}, {window}; {elapsed:.1f} s wall)"
    )
    print(format_table(summary, title))
    failures = [e["failure"] for e in episodes if e["failure"]]
    if failures:
        print(f"{len(failures)} episode(s) ended in a failure: {', '.join(sorted(set(failures)))}")
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        clean = [
            {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in e.items()}
            for e in episodes
        ]
        path.write_text(
            json.dumps(
                {
                    "env_id": args.env_id,
                    "policy": args.policy,
                    "episodes": clean,
                    "summary": {
                        k: {
                            "mean": (m if math.isfinite(m) else None),
                            "std": (s if math.isfinite(s) else None),
                        }
                        for k, (m, s) in summary.items()
                    },
                },
                indent=2,
            )
        )
        print(f"wrote {path}")
    if args.video:
        print(f"wrote {args.video}")
    return 0
