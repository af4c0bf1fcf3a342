"""The ``soft-snake`` command line, on top of the library.

Each command is a module of this package with ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> exit code``, listed once in :data:`COMMANDS`. Expected problems (a bad option, a
missing file, a policy for the wrong env: :data:`~soft_snake_gym.cli.common.USER_ERRORS`) are
reported here as one line on stderr with exit code 2 and no traceback; anything else is a bug
and keeps its traceback. The library raises; only this package prints.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from types import ModuleType

from soft_snake_gym import __version__
from soft_snake_gym.cli import (
    benchmark,
    compare,
    convergence,
    evaluate,
    figures,
    reproduce,
    robustness,
    sweep,
    train,
    tune,
)
from soft_snake_gym.cli.common import USER_ERRORS, CLIError, Parser

__all__ = ["COMMANDS", "CLIError", "build_parser", "commands", "main"]


#: The commands, in the order ``soft-snake --help`` lists them.
COMMANDS: tuple[ModuleType, ...] = (
    evaluate,
    sweep,
    figures,
    reproduce,
    train,
    compare,
    benchmark,
    convergence,
    tune,
    robustness,
)


def commands() -> dict[str, ModuleType]:
    """Name -> module of every command."""
    return {module.NAME: module for module in COMMANDS}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every command."""
    parser = Parser(
        prog="soft-snake", description="Soft segmented robots: simulate, evaluate, sweep, reproduce."
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subs = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    for name, module in commands().items():
        p = subs.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _name=name)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``soft-snake``; returns the exit code (2 for a user error)."""
    args = build_parser().parse_args(argv)

    def one_line(message, category, filename, lineno, file=None, line=None):
        print(f"soft-snake {args._name}: warning: {message}", file=sys.stderr)

    shown = warnings.showwarning
    warnings.showwarning = one_line
    try:
        return int(args._run(args) or 0)
    except USER_ERRORS as err:
        msg = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        print(f"soft-snake {args._name}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"soft-snake {args._name}: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown
