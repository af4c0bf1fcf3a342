"""The ``soft-snake`` command line, on top of the library.

Each command is a module of this package with ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> exit code``; :func:`build_parser` finds them. Expected problems (a bad option, a
missing file, a policy for the wrong env: :data:`~soft_snake_gym.cli.common.USER_ERRORS`) are
reported here as one line on stderr with exit code 2 and no traceback; anything else is a bug
and keeps its traceback. The library raises; only this package prints.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType

from soft_snake_gym.cli.common import USER_ERRORS, CLIError, Parser, env_kwargs_from_args

__all__ = ["main", "build_parser", "commands", "CLIError", "env_kwargs_from_args", "subcommand"]


def commands() -> dict[str, ModuleType]:
    """Name -> module of every command: the modules of this package that define ``NAME``."""
    found = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):  # __main__ runs the command line when imported
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "NAME"):
            found[module.NAME] = module
    return found


# TRANSITIONAL (issue 10): feature modules that still register their command themselves; removed
# once every command is a module of this package.
@dataclass(frozen=True)
class Subcommand:
    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


SUBCOMMANDS: dict[str, Subcommand] = {}


def subcommand(name: str, help: str, add_arguments: Callable[[argparse.ArgumentParser], None]):
    """TRANSITIONAL: register ``run(args) -> int`` as ``soft-snake NAME`` (decorator)."""

    def register(run: Callable[[argparse.Namespace], int]):
        SUBCOMMANDS[name] = Subcommand(name, help, add_arguments, run)
        return run

    return register


def _load_subcommands() -> None:
    for module in ("soft_snake_gym.compare", "soft_snake_gym.benchmark", "soft_snake_gym.convergence"):
        importlib.import_module(module)
# END TRANSITIONAL


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every command."""
    from soft_snake_gym import __version__

    parser = Parser(prog="soft-snake", description="Soft segmented robots: simulate, evaluate, sweep, reproduce.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subs = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    for name, module in commands().items():
        p = subs.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _name=name)
    _load_subcommands()
    for sub in SUBCOMMANDS.values():
        p = subs.add_parser(sub.name, help=sub.help, description=sub.help)
        sub.add_arguments(p)
        p.set_defaults(_run=sub.run, _name=sub.name)
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
