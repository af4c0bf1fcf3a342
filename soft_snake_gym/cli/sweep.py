"""``soft-snake sweep``: the thesis's parameter studies, resumable: CSV + heatmaps."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from pathlib import Path

from soft_snake_gym.cli.common import CLIError, add_backend_arguments, check_backend_arguments
from soft_snake_gym.studies.sweep import STUDIES, StudyGrid, default_grid, read_results, run_sweep

NAME = "sweep"
HELP = "run (or resume) the thesis's parameter studies: CSV + heatmaps"


def add_grid_arguments(p: argparse.ArgumentParser) -> None:
    """The grid options (bounds and resolution), shared with ``soft-snake reproduce``."""
    g = StudyGrid()
    p.add_argument("--alpha-min", type=float, help=f"smallest amplitude [rad] (default {g.alpha_min})")
    p.add_argument(
        "--alpha-max",
        type=float,
        help="largest amplitude [rad] (default 0.95 x the self-intersection limit, 1.52)",
    )
    p.add_argument("--n-alpha", type=int, help=f"amplitudes in the grid (default {g.n_alpha})")
    p.add_argument("--omega-min", type=float, help=f"smallest frequency [rad/s] (default {g.omega_min})")
    p.add_argument("--omega-max", type=float, help="largest frequency [rad/s] (default pi)")
    p.add_argument("--n-omega", type=int, help=f"frequencies in the grid (default {g.n_omega})")
    p.add_argument(
        "--e-bend",
        type=float,
        nargs="+",
        help=f"bending moduli of swim-stiffness [Pa] (default {' '.join(f'{e:g}' for e in g.e_bend)})",
    )
    p.add_argument(
        "--mu-min", type=float, dest="mu_s_min", help=f"smallest friction coefficient (default {g.mu_s_min})"
    )
    p.add_argument(
        "--mu-max", type=float, dest="mu_s_max", help=f"largest friction coefficient (default {g.mu_s_max})"
    )
    p.add_argument("--n-mu", type=int, help=f"friction coefficients per axis (default {g.n_mu})")
    p.add_argument("--cycles", type=int, help=f"gait cycles averaged per swimming cell (default {g.cycles})")
    p.add_argument(
        "--inch-duration", type=float, help=f"inching episode length [s] (default {g.inch_duration})"
    )


def grid_from_args(args: argparse.Namespace) -> StudyGrid:
    """The :class:`StudyGrid` of the grid options, validated."""
    keys = (
        "alpha_min",
        "alpha_max",
        "n_alpha",
        "omega_min",
        "omega_max",
        "n_omega",
        "mu_s_min",
        "mu_s_max",
        "n_mu",
        "cycles",
        "inch_duration",
    )
    kw = {k: getattr(args, k) for k in keys}
    if args.e_bend:
        kw["e_bend"] = tuple(args.e_bend)
    grid = default_grid(**kw)
    for k in ("n_alpha", "n_omega", "n_mu", "cycles"):
        if getattr(grid, k) < 1:
            raise CLIError(f"--{k.replace('_', '-')} {getattr(grid, k)} must be at least 1")
    if grid.omega_min <= 0 or grid.omega_max < grid.omega_min:
        raise CLIError(
            f"frequencies need 0 < --omega-min <= --omega-max, got {grid.omega_min}, {grid.omega_max}"
        )
    if grid.alpha_min <= 0 or (grid.alpha_max is not None and grid.alpha_max < grid.alpha_min):
        raise CLIError(
            f"amplitudes need 0 < --alpha-min <= --alpha-max, got {grid.alpha_min}, {grid.alpha_max}"
        )
    if grid.mu_s_min < 0 or grid.mu_s_max < grid.mu_s_min:
        raise CLIError(f"friction needs 0 <= --mu-min <= --mu-max, got {grid.mu_s_min}, {grid.mu_s_max}")
    if any(e <= 0 for e in grid.e_bend):
        raise CLIError(f"--e-bend values must be > 0 Pa, got {list(grid.e_bend)}")
    top = grid.alphas()[-1]
    if top >= math.pi:
        raise CLIError(
            f"--alpha-max {top:g} must be below pi rad (a serpenoid's amplitude; the body "
            "self-intersects from about 1.6 rad)"
        )
    if grid.inch_duration <= 2 * grid.inch_transient:
        raise CLIError(
            f"--inch-duration {grid.inch_duration:g} must exceed twice the {grid.inch_transient:g} s "
            "transient the metrics leave out"
        )
    return grid


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    p.add_argument("study", choices=[*STUDIES, "all"], help="which study (or all)")
    p.add_argument("--out", default="sweeps", help="output folder for CSV and PNG (default sweeps/)")
    p.add_argument(
        "--workers", type=int, help="processes, or the CPUs of a local Ray (default: all local cores)"
    )
    add_backend_arguments(p, "grid cells")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_grid_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run (or resume) the studies asked for; exit code 1 if some cells could not run."""
    grid = grid_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise CLIError(f"--workers {args.workers} must be at least 1")
    check_backend_arguments(args)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {args.out!r} is a file; give a folder for the CSV and heatmaps")
    names: Iterable[str] = STUDIES if args.study == "all" else [args.study]
    errors = 0
    for name in names:
        res = run_sweep(
            name,
            args.out,
            grid,
            workers=args.workers,
            progress=not args.no_progress,
            backend=args.backend,
            address=args.address,
        )
        print(
            f"{name}: {res['computed']} cells computed, {res['skipped']} resumed from {res['csv']} "
            f"in {res['seconds']:.1f} s; figures: {', '.join(str(p) for p in res['figures'])}"
        )
        bad = [r for r in read_results(res["csv"]).values() if str(r.get("failure", "")).startswith("error:")]
        if bad:
            errors += len(bad)
            print(
                f"{name}: {len(bad)} cells could not run, e.g. {bad[0]['key']}: {bad[0]['failure']} "
                f"(failure column of {res['csv']})",
                file=sys.stderr,
            )
    return 1 if errors else 0
