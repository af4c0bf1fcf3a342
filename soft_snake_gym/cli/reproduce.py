"""``soft-snake reproduce``.

Every sweep, both trajectory figures, the sources' headline case and docs/thesis_reproduction.md.
"""

from __future__ import annotations

import argparse

from soft_snake_gym.cli.sweep import add_grid_arguments, grid_from_args
from soft_snake_gym.studies.reproduce import headline_case, headline_table, headline_window, reproduce

NAME = "reproduce"
HELP = "run all sweeps and figures and write docs/thesis_reproduction.md"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("--out", default="docs", help="folder of thesis_reproduction.md; figures go to <out>/img")
    p.add_argument("--workers", type=int, help="processes (default: all local cores)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.add_argument(
        "--headline-only",
        action="store_true",
        help="only compute and print the sources' headline case (PID and open loop at the "
        "thesis gait, default physics and thesis preset); writes no files",
    )
    add_grid_arguments(p)


def run(args: argparse.Namespace) -> int:
    """The headline case alone, or everything and the report."""
    if args.headline_only:
        print(f"Averaged over {headline_window()}:")
        print(headline_table(headline_case()))
        return 0
    path = reproduce(args.out, workers=args.workers, progress=not args.no_progress, grid=grid_from_args(args))
    print(f"wrote {path}")
    return 0
