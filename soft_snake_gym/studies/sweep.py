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
drawn next to the CSV. The cells run in a local process pool, or as Ray tasks on a local Ray or
a cluster (``backend="ray"``, docs/scaling.md); only this process writes the CSV, so the rows
and the resume do not depend on the backend.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing as mp
import os
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from soft_snake_gym import plots
from soft_snake_gym.agents import make_policy
from soft_snake_gym.distributed import connected, imap_unordered
from soft_snake_gym.envs import register_envs
from soft_snake_gym.evaluation import NAV_METRICS, TABLE, evaluate, make_eval_env, metric_columns
from soft_snake_gym.gaits import max_serpenoid_amplitude
from soft_snake_gym.tables import appending, read_rows

__all__ = [
    "BACKENDS",
    "STUDIES",
    "Study",
    "StudyGrid",
    "control_step",
    "run_cell",
    "run_sweep",
    "read_results",
    "default_grid",
]

SOFT_E_BEND = 1.87e4
"""Bending modulus of the sources' amplitude-frequency studies [Pa]."""

SOFT_GAINS = {"Kp": 10.0, "Kd": 2.0, "Ki": 1.0}
"""PID gains the sources use at that softness (docs/model.md §9)."""

ALPHA_MAX_FRACTION = 0.95
"""The default largest amplitude, as a fraction of the serpenoid's self-intersection limit."""


@dataclass(frozen=True)
class StudyGrid:
    """Grid bounds and resolution; every field is a ``soft-snake sweep`` option."""

    alpha_min: float = 0.15
    alpha_max: float | None = None  # None: ALPHA_MAX_FRACTION x the self-intersection limit
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
        """The ``n_alpha`` amplitudes [rad] of the grid."""
        hi = (
            ALPHA_MAX_FRACTION * max_serpenoid_amplitude(10, math.pi / 4)
            if self.alpha_max is None
            else self.alpha_max
        )
        return np.round(np.linspace(self.alpha_min, hi, self.n_alpha), 4)

    def omegas(self) -> np.ndarray:
        """The ``n_omega`` frequencies [rad/s] of the grid."""
        return np.round(np.linspace(self.omega_min, self.omega_max, self.n_omega), 4)

    def mus(self) -> np.ndarray:
        """The ``n_mu`` friction coefficients of the grid."""
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
        """The study's cells on ``grid``, one dict of parameters per run."""
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
        tuple(metric_columns(("average_speed", "curvature_error", "mean_fluid_power"))),
        "swimming, amplitude x frequency, open loop vs PID (10, 2, 1), E_bend = 1.87e4 Pa",
        ("open-loop", "pid"),
    ),
    "swim-stiffness": Study(
        "swim-stiffness",
        "SoftEel-v0",
        ("alpha", "omega", "E_bend"),
        tuple(metric_columns(("average_speed", "mean_fluid_power"))),
        "swimming, open loop, amplitude x frequency for several bending moduli",
        ("open-loop",),
    ),
    "inch-friction": Study(
        "inch-friction",
        "SoftWorm-v0",
        ("mu_s", "mu_d"),
        tuple(metric_columns(("distance", "energy_friction", "length_error"))),
        "inching, static x kinetic friction, open loop vs closed loop",
        ("inching", "inching-pid"),
    ),
}

#: Where the cells can run: a local process pool, or Ray tasks (a local Ray or a cluster).
BACKENDS = ("local", "ray")

#: The CSV's result columns: the metrics of ``soft-snake evaluate``'s table but the return and the
#: navigation tasks' (no study runs them), then the episode's duration, its failure (empty if
#: none) and the cell's wall time.
RESULT_COLUMNS = (
    *(name for name in TABLE if name != "return" and name not in NAV_METRICS),
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


def control_step(env_id: str, env_kwargs: dict[str, Any] | None = None) -> float:
    """The control step ``dt`` [s] of ``env_id`` made with ``env_kwargs``, read from the env itself.

    Its ``dt``, or the integrator's step ``h``; construction warnings are left to the env that runs.
    """
    register_envs()
    kwargs = {k: v for k, v in (env_kwargs or {}).items() if k != "max_episode_steps"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id, **kwargs)
    try:
        return env.unwrapped.dt
    finally:
        env.close()


def run_cell(cell: dict[str, Any], grid: StudyGrid | None = None) -> dict[str, Any]:
    """Run one grid cell (one episode) and return the cell with its metrics."""
    grid = grid or StudyGrid()
    t0 = time.perf_counter()
    study = STUDIES[cell["study"]]
    if study.env_id == "SoftEel-v0":
        alpha, omega = cell["alpha"], cell["omega"]
        period = 2 * math.pi / omega
        transient = grid.transient_cycles * period
        peak_rate = max(alpha * omega / math.cos(alpha / 2) ** 2, 1.5 * alpha * omega)
        env_kwargs = {
            "rod": {"E_bend": cell["E_bend"]},
            "initial_shape": "straight",
            "reset_noise_scale": 0.0,
            "max_curvature_rate": max(2 * math.pi, 1.05 * peak_rate),
        }
        seconds = transient + grid.cycles * period
        opts = {"alpha": alpha, "omega": omega}
        if cell["controller"] == "pid" and cell["E_bend"] <= 1e5:
            opts.update(SOFT_GAINS)
    else:
        transient = grid.inch_transient
        env_kwargs = {
            "ground": {"mu_s": cell["mu_s"], "mu_d": cell["mu_d"]},
            "reset_noise_scale": 0.0,
        }
        seconds = grid.inch_duration
        opts = {}
    env_kwargs["max_episode_steps"] = int(round(seconds / control_step(study.env_id, env_kwargs)))
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
    out: dict[str, dict[str, Any]] = {}
    for row in read_rows(path):
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


def _run_cells(
    pending: list[dict[str, Any]],
    grid: StudyGrid,
    workers: int | None,
    backend: str,
    address: str | None,
) -> Iterator[dict[str, Any]]:
    """The rows of the ``pending`` cells, in the order they finish, on the chosen backend."""
    if not pending:
        return
    if backend == "ray":  # connected by run_sweep; a cell whose worker dies runs again, yielded once
        for _i, row in imap_unordered(_worker, [((cell, grid),) for cell in pending], max_retries=3):
            yield row
    elif workers == 1 or len(pending) == 1:
        for cell in pending:
            yield _worker((cell, grid))
    else:
        with ProcessPoolExecutor(
            max_workers=min(workers, len(pending)), mp_context=mp.get_context("spawn")
        ) as pool:
            futures = [pool.submit(_worker, (cell, grid)) for cell in pending]
            try:
                for fut in as_completed(futures):
                    yield fut.result()
            except BaseException:  # Ctrl-C, or the consumer stopped: drop what has not started
                for fut in futures:
                    fut.cancel()
                raise


def run_sweep(
    study_name: str,
    out_dir: str | Path,
    grid: StudyGrid | None = None,
    workers: int | None = None,
    progress: bool = True,
    figures: bool = True,
    backend: str = "local",
    address: str | None = None,
) -> dict[str, Any]:
    """Run (or resume) one study; returns ``{"csv", "computed", "skipped", "seconds", "figures"}``.

    The backend only decides where the cells run: the CSV, its rows and the resume are the same.

    Args:
        study_name: a key of :data:`STUDIES`.
        out_dir: folder of ``<study>.csv`` and its heatmaps.
        grid: bounds and resolution (defaults: :class:`StudyGrid`).
        workers: processes (default: the number of local cores); 1 runs in this process. With
            ``backend="ray"`` and no address: the CPUs of the local Ray.
        progress: show a tqdm bar.
        figures: draw the heatmaps afterwards.
        backend: ``"local"`` (a process pool) or ``"ray"`` (one Ray task per cell, one CPU
            each; :mod:`soft_snake_gym.distributed`).
        address: with ``backend="ray"``: the cluster to join (``host:port`` or ``"auto"``);
            None starts a local Ray.

    Raises:
        ValueError: an unknown study or backend, fewer than one worker, an address without the
            Ray backend, an unreachable address.
        RayNotInstalled: ``backend="ray"`` without Ray.
    """
    from tqdm.auto import tqdm  # here, not above: a fifth of a second to import

    if study_name not in STUDIES:
        raise ValueError(f"unknown study {study_name!r}; choose one of {', '.join(STUDIES)} or 'all'")
    if workers is not None and workers < 1:
        raise ValueError(f"workers = {workers} must be at least 1 (or None: every local core)")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) needs the Ray backend: add --backend ray")
    study = STUDIES[study_name]
    grid = grid or StudyGrid()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{study.name}.csv"
    done = read_results(path)
    cells = study.cells(grid)
    pending = [c for c in cells if cell_key(c) not in done]
    columns = _columns(study)
    workers = max(1, workers or os.cpu_count() or 1) if workers or backend == "local" else None
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if backend == "ray" and pending:  # before the CSV is touched: Ray missing, a bad address
            stack.enter_context(connected(address, num_cpus=workers if address is None else None))
        write_row = stack.enter_context(appending(path, columns))

        bar = tqdm(
            total=len(cells),
            initial=len(cells) - len(pending),
            desc=study.name,
            unit="cell",
            disable=not progress,
        )
        for row in _run_cells(pending, grid, workers, backend, address):
            write_row(dict(row, key=cell_key(row)))
            bar.update()
        bar.close()
    pngs: list[Path] = []
    if figures:
        results = read_results(path)
        rows = [results[cell_key(c)] for c in cells if cell_key(c) in results]
        pngs = plots.sweep_heatmaps(study, rows, out_dir)
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
