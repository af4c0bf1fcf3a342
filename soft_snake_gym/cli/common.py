"""What every ``soft-snake`` command shares.

The user-error type, the one-line argument parser and the env keywords of an episode command.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium

from soft_snake_gym.config import ConfigError, parse_assignments
from soft_snake_gym.distributed import RAY_INSTALL, RayNotInstalled, import_ray
from soft_snake_gym.policies import PolicyEnvMismatch

__all__ = [
    "CLIError",
    "Parser",
    "USER_ERRORS",
    "add_backend_arguments",
    "add_env_arguments",
    "check_backend_arguments",
    "env_kwargs_from_args",
]


class CLIError(Exception):
    """An expected, user-facing problem: printed as one line, exit code 2."""


#: Exception types that mean "the user asked for something impossible": one line, exit code 2.
USER_ERRORS: tuple[type[BaseException], ...] = (
    CLIError,
    ConfigError,
    PolicyEnvMismatch,
    gymnasium.error.Error,
    FileNotFoundError,
    ValueError,
    RayNotInstalled,
)


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (exit code 2)."""

    def error(self, message: str):
        """Exit with code 2 and a one-line usage error on stderr."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def add_env_arguments(p: argparse.ArgumentParser) -> None:
    """``--max-steps``, ``--env-config`` and ``--env-kwarg``: the env of an episode command."""
    p.add_argument("--max-steps", type=int, help="episode length in control steps (default: the id's)")
    p.add_argument(
        "--env-config",
        metavar="YAML",
        help="YAML file of env keywords, or a shipped one by name (softeel, softworm, eel, worm)",
    )
    p.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="env keyword, repeatable; dotted keys reach sections (rod.E_bend=1.87e4)",
    )


def env_kwargs_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The env keywords of an episode command.

    ``--env-kwarg``, ``--env-config`` and ``--max-steps`` (checked) as ``make_eval_env``'s
    ``env_kwargs``.
    """
    # dotted keys build nested sections: rod.E_bend=1.87e4 -> {"rod": {"E_bend": ...}}
    env_kwargs = parse_assignments(
        args.env_kwarg, "--env-kwarg {item} is not key=value; write e.g. --env-kwarg dt=0.02"
    )
    if args.env_config:
        env_kwargs["config"] = args.env_config
    if args.max_steps is not None:
        if args.max_steps < 1:
            raise CLIError(f"--max-steps {args.max_steps} must be at least 1")
        env_kwargs["max_episode_steps"] = args.max_steps
    return env_kwargs


def add_backend_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """``--backend {local,ray}`` and ``--address``: where a command's parallel ``what`` run."""
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help=f"run the {what} here (local, the default) or as Ray tasks (ray; needs {RAY_INSTALL})",
    )
    p.add_argument(
        "--address",
        metavar="ADDR",
        help="with --backend ray: the Ray cluster to join (host:port from `ray start --head`, or auto); "
        "default: a local Ray",
    )


def check_backend_arguments(args: argparse.Namespace) -> None:
    """Refuse ``--address`` without ``--backend ray``; check Ray is installed when asked for."""
    if args.address is not None and args.backend != "ray":
        raise CLIError(f"--address {args.address} needs --backend ray")
    if args.backend == "ray":
        import_ray()
