"""The run folder.

What a run writes (config, command, meta), its checkpoints and how a run resumes; and the
learning-curve figure drawn from it.

A run folder holds everything needed to reproduce or continue a run::

    runs/SoftEel-v0_PPO_s0/
      config.yaml          the resolved configuration (run settings and hyperparameters)
      command.txt          the exact command line
      meta.json            package version, git commit, library versions, start time
      tb/                  TensorBoard logs
      progress.csv         SB3's training log
      learning_curve.csv   agent and baseline evaluations on the same seeds
      checkpoints/         periodic model and VecNormalize statistics (resume from the last)
      best_model.zip       the best model by evaluation return (+ best_vecnormalize.pkl)
      final_model.zip      the model at the end (+ vecnormalize.pkl)
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import yaml

import soft_snake_gym
from soft_snake_gym import plots
from soft_snake_gym.agents import latest_checkpoint
from soft_snake_gym.config import ConfigError, load_yaml
from soft_snake_gym.evaluation import metric_columns
from soft_snake_gym.tables import read_rows
from soft_snake_gym.training.config import CURVE_METRICS, TrainConfig, load_train_config

__all__ = [
    "NO_CHECKOUT",
    "RUN_FILES",
    "Terminated",
    "plot_learning_curve",
    "save_checkpoint",
    "sigterm_as_interrupt",
    "stopped_by",
]


@contextlib.contextmanager
def _signals_held():
    """Ctrl-C and SIGTERM wait until the block ends (a save is never cut in half).

    Their handlers are swapped for one that only notes the signal, which the previous handler
    then gets when the block ends. Blocking them with ``pthread_sigmask`` was not enough: it
    holds them off the main thread only, the kernel hands a process's signal to any thread that
    does not block it (torch's and numba's workers), and Python then runs the handler on the
    main thread all the same. Outside the main thread (where no handler runs) the block runs as is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {
        s: signal.signal(s, lambda signum, frame: caught.append(signum))
        for s in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        if caught:
            signal.raise_signal(caught[0])


def save_checkpoint(model, run_dir: Path, started: float | None = None) -> Path:
    """Save the model and its VecNormalize statistics under ``checkpoints/``.

    With ``started`` (the run's ``time.time()`` origin) also the wall time so far, so that a resumed
    run's learning curve continues the clock (``checkpoints/wall_s.json``).

    Each file is written under a temporary name and renamed, with Ctrl-C and SIGTERM held
    meanwhile: an interrupt never leaves a half-written checkpoint for ``--resume`` to find.
    """
    ckdir = run_dir / "checkpoints"
    ckdir.mkdir(parents=True, exist_ok=True)
    steps = model.num_timesteps
    path = ckdir / f"model_{steps}_steps.zip"
    with _signals_held():
        vn = model.get_vec_normalize_env()
        if vn is not None:  # before the model: a checkpoint's model never lacks its statistics
            _written(ckdir / f"vecnormalize_{steps}_steps.pkl", lambda partial: vn.save(str(partial)))
        _written(path, model.save)
        if started is not None:
            walls = _checkpoint_walls(run_dir)
            walls[str(steps)] = round(time.time() - started, 1)
            _written(
                ckdir / "wall_s.json", lambda partial: partial.write_text(json.dumps(walls, indent=1) + "\n")
            )
    return path


def _written(path: Path, write) -> None:
    """Write ``path`` by ``write(partial)`` under a temporary name beside it, then rename it into place."""
    partial = path.with_name(f"{path.stem}.partial{path.suffix}")
    write(partial)
    os.replace(partial, path)


def _checkpoint_walls(run_dir: Path) -> dict[str, float]:
    """Training wall time [s] at each checkpoint, by step count."""
    path = run_dir / "checkpoints" / "wall_s.json"
    return json.loads(path.read_text()) if path.is_file() else {}


class Terminated(KeyboardInterrupt):
    """Training stopped by SIGTERM (a scheduler or ``kill``): handled as Ctrl-C, a checkpoint is saved first."""


def stopped_by(err: KeyboardInterrupt) -> signal.Signals:
    """The signal behind an interrupt: SIGTERM for :class:`Terminated`, else SIGINT (Ctrl-C).

    A command stopped by it exits with ``128 + stopped_by(err)``, as a shell reports a signal.
    """
    return signal.SIGTERM if isinstance(err, Terminated) else signal.SIGINT


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises :class:`Terminated`.

    Once; a repeat is ignored while what was done is saved (a checkpoint, a benchmark's results).
    Outside the main thread, signals stay as they are.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Terminated(f"stopped by signal {signal.Signals(signum).name}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


# --- the run --------------------------------------------------------------------------------
NO_CHECKOUT = "none: the package is not a git checkout (an installed copy); see soft_snake_gym's version"


def _git_commit(package_dir: Path | None = None) -> str:
    """The commit of the git checkout the package runs from, or :data:`NO_CHECKOUT`.

    :data:`NO_CHECKOUT` when it runs from an installed copy (``pip install .``) or git is missing. A
    checkout counts only if it tracks the package itself, not merely encloses it (a venv inside
    another repo).
    """
    where = package_dir or Path(__file__).resolve().parents[1]
    try:
        tracked = subprocess.run(
            ["git", "ls-files", "--error-unmatch", "__init__.py"],
            cwd=where,
            capture_output=True,
            text=True,
            timeout=5,
        )
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=5
        )
    except (OSError, subprocess.SubprocessError):
        return NO_CHECKOUT
    if tracked.returncode != 0 or head.returncode != 0 or not head.stdout.strip():
        return NO_CHECKOUT
    return head.stdout.strip()


def _is_new_stage(cfg: TrainConfig, run_dir: Path) -> bool:
    """True if ``cfg`` changes settings other than ``n_timesteps`` of the run's config.yaml."""
    path = run_dir / "config.yaml"

    def settings(data: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in next(iter(data.values())).items() if k != "n_timesteps"}

    return path.is_file() and settings(load_yaml(path)) != settings(cfg.to_yaml_dict())


def _command_line(command: list[str] | None) -> str:
    """The command that started the run (default ``sys.argv``), as a user types it.

    The CLI's own path (the ``soft-snake`` console script, or ``soft_snake_gym/cli/__main__.py``
    under ``python -m soft_snake_gym.cli``) is recorded as ``soft-snake``, so that a run folder
    (and a shipped agent's ``command.txt``) names no path of the machine that trained it.
    """
    argv = list(sys.argv if command is None else command)
    if argv and (
        Path(argv[0]).name == "soft-snake"
        or Path(argv[0]).parts[-3:] == ("soft_snake_gym", "cli", "__main__.py")
    ):
        argv[0] = "soft-snake"
    return shlex.join(argv)


def _record_resume(cfg: TrainConfig, run_dir: Path, command: list[str] | None) -> bool:
    """Append the resuming command to command.txt.

    If settings other than ``n_timesteps`` changed (a curriculum: ``--resume DIR --hyperparams
    ...``), keep the earlier config.yaml as config.<k>.yaml and return True: a new stage begins.
    """
    path = run_dir / "config.yaml"
    new_stage = _is_new_stage(cfg, run_dir)
    if new_stage:
        k = 1
        while (run_dir / f"config.{k}.yaml").exists():
            k += 1
        path.rename(run_dir / f"config.{k}.yaml")
    path.write_text(yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False))
    with open(run_dir / "command.txt", "a") as fh:
        fh.write(_command_line(command) + "\n")
    return new_stage


#: The files a run writes: a folder holding only these and no checkpoint may be reused.
RUN_FILES = (
    "config.yaml",
    "command.txt",
    "meta.json",
    "tb",
    "progress.csv",
    "learning_curve.csv",
    "learning_curve.png",
    "checkpoints",
    "best_model.zip",
    "best_vecnormalize.pkl",
    "final_model.zip",
    "vecnormalize.pkl",
)


def _check_new_run_dir(run_dir: Path) -> None:
    """Check that a new run may start in ``run_dir``.

    A new run may start in a missing or empty folder, or in a folder of a run that left no
    checkpoint (it failed or was stopped before its first one).
    """
    if not run_dir.exists():
        return
    if not run_dir.is_dir():
        raise ConfigError(f"run folder {str(run_dir)!r} is a file; choose another --run-dir")
    if latest_checkpoint(run_dir) is not None:
        raise ConfigError(
            f"run folder {str(run_dir)!r} already holds a run with checkpoints; "
            "pass --resume to continue it or choose another --run-dir"
        )
    other = sorted(
        p.name
        for p in run_dir.iterdir()
        if p.name not in RUN_FILES and not (p.name.startswith(("config.", "progress.")))
    )
    if other:
        raise ConfigError(
            f"run folder {str(run_dir)!r} is not empty and not a run folder (it holds {', '.join(other[:3])}"
            f"{', ...' if len(other) > 3 else ''}); choose another --run-dir"
        )


def _clear_run_files(run_dir: Path) -> None:
    """Remove what an earlier run without checkpoints left, so the logs do not mix runs."""
    if not run_dir.is_dir():
        return
    for p in run_dir.iterdir():
        if p.name in RUN_FILES or p.name.startswith(("config.", "progress.")):
            shutil.rmtree(p) if p.is_dir() else p.unlink()


def _write_run_files(cfg: TrainConfig, run_dir: Path, command: list[str] | None) -> None:
    import stable_baselines3  # here, not above: SB3 and torch take seconds to import
    import torch

    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.yaml").write_text(yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False))
    (run_dir / "command.txt").write_text(_command_line(command) + "\n")
    meta = {
        "soft_snake_gym": soft_snake_gym.__version__,
        "git_commit": _git_commit(),
        "python": platform.python_version(),
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (run_dir / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")


def _make_logger(run_dir: Path):
    """SB3's logger writing progress.csv into the run folder and TensorBoard into tb/.

    A resumed run moves the earlier progress.csv aside (progress.1.csv, ...) instead of overwriting
    it.
    """
    # here, not above: SB3 and torch take seconds to import
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat

    csv_path = run_dir / "progress.csv"
    if csv_path.is_file():
        k = 1
        while (run_dir / f"progress.{k}.csv").exists():
            k += 1
        csv_path.rename(run_dir / f"progress.{k}.csv")
    return Logger(
        str(run_dir), [CSVOutputFormat(str(csv_path)), TensorBoardOutputFormat(str(run_dir / "tb"))]
    )


def plot_learning_curve(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Plot a run's learning_curve.csv (:func:`soft_snake_gym.plots.learning_curve`).

    Written next to the CSV by default.

    Raises:
        ConfigError: the CSV has no evaluations yet.
    """
    run_dir = Path(run_dir)
    rows = read_rows(run_dir / "learning_curve.csv")
    if not rows:
        raise ConfigError(f"{run_dir / 'learning_curve.csv'} has no evaluations yet")
    cfg = load_train_config(next(iter(load_yaml(run_dir / "config.yaml"))), path=run_dir / "config.yaml")
    out = Path(out) if out is not None else run_dir / "learning_curve.png"
    return plots.learning_curve(rows, cfg, metric_columns(CURVE_METRICS[1:]), out)
