"""The thesis's parameter studies (docs/model.md §9) as resumable, parallel grids of episodes.

Studies:

- ``swim-gait``: swimming, amplitude alpha x frequency omega, open loop and curvature PID,
  at the bending modulus E_bend = 1.87e4 Pa of the sources' captions (PID gains (10, 2, 1),
  docs/model.md §9): average speed, curvature error, mean fluid power.
- ``swim-stiffness``: swimming, open loop, alpha x omega for several bending moduli: average
  speed.
- ``inch-friction``: inching, mu_s x mu_d (mu_d <= mu_s), open and closed loop: distance and
  friction energy.

Each cell is one episode run by :func:`soft_snake_gym.evaluation.evaluate`. A swimming cell
starts straight and at rest, and lasts ``transient_cycles + cycles`` gait periods; speed,
error and power are taken over the last ``cycles`` periods (a whole number, so the averages
are not biased by where a cycle is cut). The env's ``max_curvature_rate`` is raised where
needed so that neither the open-loop rate nor the PID saturation ``1.5 alpha omega`` is clipped.

Every finished cell is appended to ``<out>/<study>.csv`` at once (flushed), so an interrupted
sweep keeps it; a rerun reads the CSV and computes only the missing cells. Heatmaps (PNG) are
drawn next to the CSV.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.cli import CLIError, subcommand

__all__ = ["STUDIES", "Study", "StudyGrid", "run_cell", "run_sweep", "read_results", "default_grid"]

SOFT_E_BEND = 1.87e4
"""Bending modulus of the sources' amplitude-frequency studies [Pa]."""

SOFT_GAINS = {"Kp": 10.0, "Kd": 2.0, "Ki": 1.0}
"""PID gains the sources use at that softness (docs/model.md §9)."""


@dataclass(frozen=True)
class StudyGrid:
    """Grid bounds and resolution; every field is a ``soft-snake sweep`` option."""

    alpha_min: float = 0.15
    alpha_max: float | None = None  # None: 0.95 x the self-intersection limit
    n_alpha: int = 8
    omega_min: float = 0.5
    omega_max: float = math.pi
    n_omega: int = 8
    e_bend: tuple[float, ...] = (1.87e4, 1.87e5, 1.875e6)
    mu_s_min: float = 0.2
    mu_s_max: float = 1.2
    n_mu: int = 6
    cycles: int = 2
    transient_cycles: int = 1
    inch_duration: float = 10.0
    inch_transient: float = 1.0

    def alphas(self) -> np.ndarray:
        from soft_snake_gym.gaits import max_serpenoid_amplitude

        hi = 0.95 * max_serpenoid_amplitude(10, math.pi / 4) if self.alpha_max is None else self.alpha_max
        return np.round(np.linspace(self.alpha_min, hi, self.n_alpha), 4)

    def omegas(self) -> np.ndarray:
        return np.round(np.linspace(self.omega_min, self.omega_max, self.n_omega), 4)

    def mus(self) -> np.ndarray:
        return np.round(np.linspace(self.mu_s_min, self.mu_s_max, self.n_mu), 4)


@dataclass(frozen=True)
class Study:
    """One parameter study: its grid axes, controllers and reported metrics."""

    name: str
    env_id: str
    params: tuple[str, ...]  # grid columns (besides "controller")
    metrics: tuple[tuple[str, str, str], ...]  # (key, label, unit)
    description: str
    controllers: tuple[str, ...] = field(default=())

    def cells(self, grid: StudyGrid) -> list[dict[str, Any]]:
        out = []
        if self.name == "swim-gait":
            for c in self.controllers:
                for a in grid.alphas():
                    for w in grid.omegas():
                        out.append(
                            {"controller": c, "alpha": float(a), "omega": float(w), "E_bend": SOFT_E_BEND}
                        )
        elif self.name == "swim-stiffness":
            for e in grid.e_bend:
                for a in grid.alphas():
                    for w in grid.omegas():
                        out.append(
                            {
                                "controller": "open-loop",
                                "alpha": float(a),
                                "omega": float(w),
                                "E_bend": float(e),
                            }
                        )
        elif self.name == "inch-friction":
            mus = grid.mus()
            for c in self.controllers:
                for ms in mus:
                    for md in mus:
                        if md <= ms + 1e-12:
                            out.append({"controller": c, "mu_s": float(ms), "mu_d": float(md)})
        return [dict(cell, study=self.name) for cell in out]


STUDIES: dict[str, Study] = {
    "swim-gait": Study(
        "swim-gait",
        "SoftEel-v0",
        ("alpha", "omega", "E_bend"),
        (
            ("average_speed", "average speed", "m/s"),
            ("curvature_error", "curvature error", "-"),
            ("mean_fluid_power", "fluid power", "W"),
        ),
        "swimming, amplitude x frequency, open loop vs PID (10, 2, 1), E_bend = 1.87e4 Pa",
        ("open-loop", "pid"),
    ),
    "swim-stiffness": Study(
        "swim-stiffness",
        "SoftEel-v0",
        ("alpha", "omega", "E_bend"),
        (("average_speed", "average speed", "m/s"), ("mean_fluid_power", "fluid power", "W")),
        "swimming, open loop, amplitude x frequency for several bending moduli",
        ("open-loop",),
    ),
    "inch-friction": Study(
        "inch-friction",
        "SoftWorm-v0",
        ("mu_s", "mu_d"),
        (
            ("distance", "distance", "m"),
            ("energy_friction", "friction energy", "J"),
            ("length_error", "length error", "m"),
        ),
        "inching, static x kinetic friction, open loop vs closed loop",
        ("inching", "inching-pid"),
    ),
}

RESULT_COLUMNS = (
    "average_speed",
    "distance",
    "curvature_error",
    "length_error",
    "mean_fluid_power",
    "energy_fluid",
    "energy_friction",
    "energy_actuator",
    "cost_of_transport",
    "duration",
    "failure",
    "wall_time",
)


def cell_key(cell: dict[str, Any]) -> str:
    """A stable text id of a cell (its study, controller and rounded parameters)."""
    parts = [cell["study"], cell["controller"]]
    for k in STUDIES[cell["study"]].params:
        parts.append(f"{k}={float(cell[k]):.6g}")
    return "|".join(parts)


def run_cell(cell: dict[str, Any], grid: StudyGrid | None = None) -> dict[str, Any]:
    """Run one grid cell (one episode) and return the cell with its metrics."""
    from soft_snake_gym.evaluation import evaluate, make_eval_env
    from soft_snake_gym.agents import make_policy

    grid = grid or StudyGrid()
    t0 = time.perf_counter()
    study = STUDIES[cell["study"]]
    if study.env_id == "SoftEel-v0":
        alpha, omega = cell["alpha"], cell["omega"]
        period = 2 * math.pi / omega
        transient = grid.transient_cycles * period
        steps = int(round((transient + grid.cycles * period) / 0.01))
        peak_rate = max(alpha * omega / math.cos(alpha / 2) ** 2, 1.5 * alpha * omega)
        env_kwargs = {
            "rod": {"E_bend": cell["E_bend"]},
            "initial_shape": "straight",
            "reset_noise_scale": 0.0,
            "max_curvature_rate": max(2 * math.pi, 1.05 * peak_rate),
            "max_episode_steps": steps,
        }
        opts = {"alpha": alpha, "omega": omega}
        if cell["controller"] == "pid" and cell["E_bend"] <= 1e5:
            opts.update(SOFT_GAINS)
    else:
        transient = grid.inch_transient
        env_kwargs = {
            "ground": {"mu_s": cell["mu_s"], "mu_d": cell["mu_d"]},
            "reset_noise_scale": 0.0,
            "max_episode_steps": int(round(grid.inch_duration / 0.01)),
        }
        opts = {}
    env = make_eval_env(study.env_id, seed=0, env_kwargs=env_kwargs)
    spec = cell["controller"] + (":" + ",".join(f"{k}={v!r}" for k, v in opts.items()) if opts else "")
    policy = make_policy(spec, env)
    episode = evaluate(policy, env, episodes=1, transient=transient)[0]
    env.close()
    row = dict(cell)
    for k in RESULT_COLUMNS:
        row[k] = episode.get(k, "")
    row["wall_time"] = round(time.perf_counter() - t0, 3)
    return row


def _columns(study: Study) -> list[str]:
    return ["key", "study", "controller", *study.params, *RESULT_COLUMNS]


def read_results(path: str | Path) -> dict[str, dict[str, Any]]:
    """Finished cells of a sweep CSV, by key (a torn last line is ignored)."""
    path = Path(path)
    out: dict[str, dict[str, Any]] = {}
    if not path.is_file():
        return out
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        for row in reader:
            if not row.get("key") or row.get("wall_time") in (None, ""):
                continue
            parsed: dict[str, Any] = {}
            for k, v in row.items():
                if k in ("key", "study", "controller", "failure"):
                    parsed[k] = v
                else:
                    try:
                        parsed[k] = float(v)
                    except (TypeError, ValueError):
                        parsed[k] = math.nan
            out[row["key"]] = parsed
    return out


def _worker(args: tuple[dict[str, Any], StudyGrid]) -> dict[str, Any]:
    cell, grid = args
    try:
        return run_cell(cell, grid)
    except Exception as err:  # noqa: BLE001 - a cell that cannot run is recorded, not fatal
        row = dict(cell)
        for k in RESULT_COLUMNS:
            row[k] = ""
        row["failure"] = f"error: {type(err).__name__}: {err}"[:200]
        row["wall_time"] = 0.0
        return row


def run_sweep(
    study_name: str,
    out_dir: str | Path,
    grid: StudyGrid | None = None,
    workers: int | None = None,
    progress: bool = True,
    figures: bool = True,
) -> dict[str, Any]:
    """Run (or resume) one study; returns ``{"csv", "computed", "skipped", "seconds", "figures"}``.

    Args:
        study_name: a key of :data:`STUDIES`.
        out_dir: folder of ``<study>.csv`` and its heatmaps.
        grid: bounds and resolution (defaults: :class:`StudyGrid`).
        workers: processes (default: the number of local cores); 1 runs in this process.
        progress: show a tqdm bar.
        figures: draw the heatmaps afterwards.
    """
    from tqdm.auto import tqdm

    if study_name not in STUDIES:
        raise CLIError(f"unknown study {study_name!r}; choose one of {', '.join(STUDIES)} or 'all'")
    if workers is not None and workers < 1:
        raise CLIError(f"workers = {workers} must be at least 1 (or None: every local core)")
    study = STUDIES[study_name]
    grid = grid or StudyGrid()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{study.name}.csv"
    done = read_results(path)
    cells = study.cells(grid)
    pending = [c for c in cells if cell_key(c) not in done]
    columns = _columns(study)
    workers = max(1, workers or os.cpu_count() or 1)
    t0 = time.perf_counter()
    new_file = not path.is_file() or path.stat().st_size == 0
    with path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        if new_file:
            writer.writeheader()
            f.flush()

        def write(row: dict[str, Any]) -> None:
            row = dict(row, key=cell_key(row))
            writer.writerow({k: row.get(k, "") for k in columns})
            f.flush()
            os.fsync(f.fileno())

        bar = tqdm(
            total=len(cells),
            initial=len(cells) - len(pending),
            desc=study.name,
            unit="cell",
            disable=not progress,
        )
        if workers == 1 or len(pending) <= 1:
            for cell in pending:
                write(_worker((cell, grid)))
                bar.update()
        elif pending:
            import multiprocessing as mp

            with ProcessPoolExecutor(
                max_workers=min(workers, len(pending)), mp_context=mp.get_context("spawn")
            ) as pool:
                futures = [pool.submit(_worker, (cell, grid)) for cell in pending]
                try:
                    for fut in as_completed(futures):
                        write(fut.result())
                        bar.update()
                except KeyboardInterrupt:
                    for fut in futures:
                        fut.cancel()
                    raise
        bar.close()
    pngs: list[Path] = []
    if figures:
        from soft_snake_gym.figures import sweep_heatmaps

        results = read_results(path)
        rows = [results[cell_key(c)] for c in cells if cell_key(c) in results]
        pngs = sweep_heatmaps(study, rows, out_dir)
    return {
        "csv": path,
        "computed": len(pending),
        "skipped": len(cells) - len(pending),
        "seconds": time.perf_counter() - t0,
        "figures": pngs,
    }


def default_grid(**overrides: Any) -> StudyGrid:
    """A :class:`StudyGrid` with the given fields replaced."""
    return StudyGrid(**{k: v for k, v in overrides.items() if v is not None})


# --- CLI ----------------------------------------------------------------------------------------
def _grid_arguments(p: argparse.ArgumentParser) -> None:
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


def _sweep_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("study", choices=[*STUDIES, "all"], help="which study (or all)")
    p.add_argument("--out", default="sweeps", help="output folder for CSV and PNG (default sweeps/)")
    p.add_argument("--workers", type=int, help="processes (default: all local cores)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    _grid_arguments(p)


@subcommand("sweep", "run (or resume) the thesis's parameter studies: CSV + heatmaps", _sweep_arguments)
def _sweep(args: argparse.Namespace) -> int:
    grid = grid_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise CLIError(f"--workers {args.workers} must be at least 1")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {args.out!r} is a file; give a folder for the CSV and heatmaps")
    names: Iterable[str] = STUDIES if args.study == "all" else [args.study]
    errors = 0
    for name in names:
        res = run_sweep(name, args.out, grid, workers=args.workers, progress=not args.no_progress)
        print(
            f"{name}: {res['computed']} cells computed, {res['skipped']} resumed from {res['csv']} "
            f"in {res['seconds']:.1f} s; figures: {', '.join(str(p) for p in res['figures'])}"
        )
        bad = [r for r in read_results(res["csv"]).values() if str(r.get("failure", "")).startswith("error:")]
        if bad:
            errors += len(bad)
            print(f"{name}: {len(bad)} cells could not run, e.g. {bad[0]['key']}: {bad[0]['failure']} "
                  f"(failure column of {res['csv']})", file=sys.stderr)
    return 1 if errors else 0
