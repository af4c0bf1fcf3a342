"""The ``soft-snake`` command line.

Each subcommand is a pair of small functions, ``add_arguments(parser)`` and ``run(args) ->
exit code``, registered once in :data:`SUBCOMMANDS` with :func:`subcommand`. Expected
problems (a bad option, a missing file, a policy for the wrong env) are reported as one line
on stderr with exit code 2 and no traceback; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["main", "subcommand", "SUBCOMMANDS", "CLIError"]


class CLIError(Exception):
    """An expected, user-facing problem: printed as one line, exit code 2."""


@dataclass(frozen=True)
class Subcommand:
    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


#: name -> subcommand; add one with :func:`subcommand`.
SUBCOMMANDS: dict[str, Subcommand] = {}


def subcommand(name: str, help: str, add_arguments: Callable[[argparse.ArgumentParser], None]):
    """Register ``run(args) -> int`` as ``soft-snake NAME`` (decorator)."""

    def register(run: Callable[[argparse.Namespace], int]):
        SUBCOMMANDS[name] = Subcommand(name, help, add_arguments, run)
        return run

    return register


def _user_errors() -> tuple[type[BaseException], ...]:
    """Exception types that mean "the user asked for something impossible"."""
    import gymnasium

    from soft_snake_gym.config import ConfigError
    from soft_snake_gym.policies import PolicyEnvMismatch

    return (CLIError, ConfigError, PolicyEnvMismatch, gymnasium.error.Error, FileNotFoundError,
            ValueError)


# --- evaluate -----------------------------------------------------------------------------------
def _parse_env_kwargs(items: list[str]) -> dict[str, Any]:
    from soft_snake_gym.policies.base import parse_value

    out: dict[str, Any] = {}
    for item in items or []:
        key, eq, value = item.partition("=")
        if not eq:
            raise CLIError(f"--env-kwarg {item!r} is not key=value; write e.g. --env-kwarg dt=0.02")
        # dotted keys build nested sections: rod.E_bend=1.87e4 -> {"rod": {"E_bend": ...}}
        node = out
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = parse_value(value)
    return out


def env_kwargs_from_args(args) -> dict[str, Any]:
    """The env keywords of an episode command: ``--env-kwarg``, ``--env-config`` and
    ``--max-steps`` (checked) as ``make_eval_env``'s ``env_kwargs``."""
    env_kwargs = _parse_env_kwargs(args.env_kwarg)
    if args.env_config:
        env_kwargs["config"] = args.env_config
    if args.max_steps is not None:
        if args.max_steps < 1:
            raise CLIError(f"--max-steps {args.max_steps} must be at least 1")
        env_kwargs["max_episode_steps"] = args.max_steps
    return env_kwargs


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("env_id", help="environment id, e.g. SoftEel-v0 or SoftWorm-v0")
    p.add_argument("--policy", required=True,
                   help="baseline name with options (pid, 'pid:alpha=0.5,omega=2.1', decentralized, "
                        "'decentralized:closure=pacemaker', open-loop, inching, inching-pid) "
                        "or the path to a saved SB3 model (.zip)")
    p.add_argument("--policy-config", metavar="YAML", help="YAML file of the policy's gait/gains")
    p.add_argument("--episodes", type=int, default=3, help="number of episodes (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--transient", type=float,
                   help="start-up time left out of speed and error [s] (default 2, or half the "
                        "episode if that is shorter)")
    p.add_argument("--max-steps", type=int, help="episode length in control steps (default: the id's)")
    p.add_argument("--env-config", metavar="YAML", help="YAML file of env keywords")
    p.add_argument("--env-kwarg", action="append", metavar="KEY=VALUE",
                   help="env keyword, repeatable; dotted keys reach sections (rod.E_bend=1.87e4)")
    p.add_argument("--start-on-gait", action="store_true",
                   help="start at rest on the policy's own serpenoid gait (curvatures = desired at t = 0, "
                        "no start noise): the env keyword start_on_gait, for open-loop, pid, decentralized")
    p.add_argument("--json", metavar="PATH", help="also write the per-episode metrics and summary")
    p.add_argument("--video", metavar="PATH", help="record the first episode (.mp4 or .gif)")


@subcommand("evaluate", "evaluate a baseline or a trained model for K episodes", _evaluate_arguments)
def _evaluate(args: argparse.Namespace) -> int:
    from soft_snake_gym.evaluation import (
        check_transient,
        check_video_path,
        evaluate,
        format_table,
        make_eval_env,
        summarize,
    )
    from soft_snake_gym.policies import make_policy, policy_gait

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
            raise CLIError("--start-on-gait takes the gait from the policy; drop --env-kwarg start_on_gait...")
        env_kwargs["start_on_gait"] = policy_gait(args.policy, args.policy_config)
    env = make_eval_env(args.env_id, seed=args.seed, env_kwargs=env_kwargs,
                        render_mode="rgb_array" if args.video else None)
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
        window += (f" (over the whole episode for {whole} of {len(episodes)} that ended before "
                   f"{2 * args.transient:g} s)")
    durations = sorted({round(e["duration"], 1) for e in episodes})
    each = f"{durations[0]:.1f} s each" if len(durations) == 1 else f"{durations[0]:.1f}-{durations[-1]:.1f} s"
    title = (f"{args.env_id}  policy={args.policy}  episodes={args.episodes}  "
             f"({each}, {window}; {elapsed:.1f} s wall)")
    print(format_table(summary, title))
    failures = [e["failure"] for e in episodes if e["failure"]]
    if failures:
        print(f"{len(failures)} episode(s) ended in a failure: {', '.join(sorted(set(failures)))}")
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        clean = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in e.items()}
                 for e in episodes]
        path.write_text(json.dumps({
            "env_id": args.env_id, "policy": args.policy, "episodes": clean,
            "summary": {k: {"mean": (m if math.isfinite(m) else None), "std": (s if math.isfinite(s) else None)}
                        for k, (m, s) in summary.items()},
        }, indent=2))
        print(f"wrote {path}")
    if args.video:
        print(f"wrote {args.video}")
    return 0


# --- entry point --------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (exit code 2)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    from soft_snake_gym import __version__

    parser = _Parser(
        prog="soft-snake", description="Soft segmented robots: simulate, evaluate, sweep, reproduce."
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subs = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)
    for sub in SUBCOMMANDS.values():
        p = subs.add_parser(sub.name, help=sub.help, description=sub.help)
        sub.add_arguments(p)
        p.set_defaults(_run=sub.run, _name=sub.name)
    return parser


def _load_subcommands() -> None:
    """Import the modules that register further subcommands."""
    import importlib

    for module in ("soft_snake_gym.sweep", "soft_snake_gym.figures", "soft_snake_gym.reproduce",
                   "soft_snake_gym.training", "soft_snake_gym.compare", "soft_snake_gym.benchmark",
                   "soft_snake_gym.convergence"):
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:
                raise


def main(argv: list[str] | None = None) -> int:
    """Run ``soft-snake``; returns the exit code (2 for a user error)."""
    _load_subcommands()
    parser = build_parser()
    args = parser.parse_args(argv)

    def one_line(message, category, filename, lineno, file=None, line=None):
        print(f"soft-snake {args._name}: warning: {message}", file=sys.stderr)

    shown = warnings.showwarning
    warnings.showwarning = one_line
    try:
        return int(args._run(args) or 0)
    except _user_errors() as err:
        msg = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        print(f"soft-snake {args._name}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"soft-snake {args._name}: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":  # python -m soft_snake_gym.cli: use the importable module's registry
    from soft_snake_gym.cli import main as _main

    sys.exit(_main())
