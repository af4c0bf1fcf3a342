"""``soft-snake figures``: the swimming snapshot and centralized-vs-decentralized figures."""

from __future__ import annotations

import argparse

from soft_snake_gym.studies.figures import make_all_figures

NAME = "figures"
HELP = "draw the swimming snapshot and centralized-vs-decentralized figures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("--out", default="docs/img", help="folder for the PNGs (default docs/img)")


def run(args: argparse.Namespace) -> int:
    """Draw both figures and print their paths and the comparison's errors."""
    res = make_all_figures(args.out)
    print(f"wrote {res['snapshots']} and {res['comparison']}")
    e = res["comparison_errors"]
    print(
        f"mean curvature error after 2 s: centralized {e['centralized']:.4f}, "
        f"decentralized {e['decentralized']:.4f}"
    )
    return 0
