"""One training run per seed: seed ranges, their run folders, and running them here or on Ray.

``soft-snake train ENV --seeds 0-7`` trains the same configuration with seeds 0 to 7, each in
its own run folder ``<parent>/s<seed>`` (a complete run folder, as :func:`train` writes it).
On the local backend the seeds run one after another in this process (each training already
uses the machine's cores through its vectorized envs); on the Ray backend each seed is one Ray
task of one CPU, run in parallel over the cluster's CPUs. A seed whose Ray worker dies is run
again (``max_retries``) and resumes from its last checkpoint.
"""

from __future__ import annotations

import dataclasses
import re
import sys
from collections.abc import Callable
from pathlib import Path

from soft_snake_gym.config import ConfigError
from soft_snake_gym.distributed import connected, imap_unordered
from soft_snake_gym.training.config import TrainConfig
from soft_snake_gym.training.run import _check_new_run_dir, latest_checkpoint
from soft_snake_gym.training.train import train

__all__ = ["parse_seeds", "seed_run_dir", "train_seeds"]

_RANGE = re.compile(r"^\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?$")


def parse_seeds(text: str) -> list[int]:
    """The seeds of ``"0-7"``, ``"3"`` or ``"0-3,8,10-11"`` (ranges inclusive), in order.

    Raises:
        ConfigError: not a list of seeds or ranges, a range whose end is below its start, a
            negative or repeated seed.
    """
    seeds: list[int] = []
    for part in str(text).split(","):
        m = _RANGE.match(part)
        if not m:
            raise ConfigError(
                f"--seeds {text!r}: {part.strip()!r} is not a seed or a range; write e.g. 0-7 or 0,2,5"
            )
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) is not None else lo
        if hi < lo:
            raise ConfigError(f"--seeds {text!r}: the range {lo}-{hi} ends below its start; write {hi}-{lo}")
        if lo < 0:
            raise ConfigError(f"--seeds {text!r}: seeds must be >= 0, got {lo}")
        seeds.extend(range(lo, hi + 1))
    repeated = sorted({s for s in seeds if seeds.count(s) > 1})
    if repeated:
        raise ConfigError(f"--seeds {text!r}: names seed {repeated[0]} twice")
    return seeds


def seed_run_dir(parent: str | Path, seed: int) -> Path:
    """The run folder of ``seed`` under ``parent``: ``<parent>/s<seed>``."""
    return Path(parent) / f"s{seed}"


def _train_seed(cfg: TrainConfig, run_dir: Path, command: list[str]) -> str:
    """Train one seed (a Ray task); a retried task resumes from the checkpoint its first try left."""
    resume = latest_checkpoint(run_dir) is not None if run_dir.is_dir() else False
    return str(train(cfg, run_dir, resume=resume, progress=False, command=command))


def train_seeds(
    cfg: TrainConfig,
    seeds: list[int],
    parent: str | Path,
    backend: str = "local",
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    command: list[str] | None = None,
    on_done: Callable[[int, Path], None] | None = None,
) -> dict[int, Path]:
    """Train ``cfg`` once per seed, each in ``<parent>/s<seed>``; returns seed -> final model path.

    Every folder is checked before any training starts.

    Args:
        cfg: the configuration; its ``seed`` is replaced by each seed.
        seeds: the seeds (:func:`parse_seeds`).
        parent: the folder of the run folders.
        backend: ``"local"`` (one seed after another, here) or ``"ray"`` (one Ray task of one
            CPU per seed, in parallel).
        address: with ``backend="ray"``: the cluster to join; None starts a local Ray.
        workers: the CPUs of a local Ray (default: every core).
        progress: a progress bar per training (local backend only).
        command: recorded in each run folder's command.txt (default: ``sys.argv``).
        on_done: called with (seed, final model path) as each seed finishes.

    Raises:
        ConfigError: no seeds, a folder that holds another run.
        ValueError: an unknown backend, an address without the Ray backend or unreachable.
        RayNotInstalled: ``backend="ray"`` without Ray.
    """
    if backend not in ("local", "ray"):
        raise ValueError(f"unknown backend {backend!r}; choose local or ray")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) needs the Ray backend: add --backend ray")
    if not seeds:
        raise ConfigError("no seeds to train")
    parent = Path(parent).resolve()  # Ray workers do not share this process's working folder
    runs = {s: (dataclasses.replace(cfg, seed=s), seed_run_dir(parent, s)) for s in seeds}
    for _, run_dir in runs.values():
        _check_new_run_dir(run_dir)
    command = list(command if command is not None else sys.argv)
    done: dict[int, Path] = {}
    if backend == "local":
        for s, (c, run_dir) in runs.items():
            done[s] = train(c, run_dir, progress=progress, command=command)
            if on_done:
                on_done(s, done[s])
        return done
    order = list(runs)
    with connected(address, num_cpus=workers if address is None else None):
        tasks = [(c, run_dir, command) for c, run_dir in runs.values()]
        for i, final in imap_unordered(_train_seed, tasks, num_cpus=1, max_retries=2):
            done[order[i]] = Path(final)
            if on_done:
                on_done(order[i], done[order[i]])
    return dict(sorted(done.items()))
