"""Wall times of docs/scaling.md: a sweep and 4 seeds on 1 and 2 Ray workers, and the numba cache.

Runs the real commands (``python -m soft_snake_gym.cli ...``) one after another and prints a
Markdown table. Needs the ``ray`` extra. Run it under ``unshare -n sh -c 'ip link set lo up &&
python scripts/bench_scaling.py'`` (as root) to keep Ray on loopback.

    python scripts/bench_scaling.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SWEEP = ["sweep", "swim-gait", "--n-alpha", "4", "--n-omega", "4", "--cycles", "1", "--no-progress"]
SEEDS = [
    "train",
    "SoftEel-v0",
    "--seeds",
    "0-3",
    "--n-timesteps",
    "4096",
    "--no-progress",
    "--hyperparams",
    "n_envs=4",
    "n_steps=256",
    "batch_size=256",
    "eval_freq=2048",
    "checkpoint_freq=2048",
    "eval_episodes=2",
]


def run(args: list[str], env: dict | None = None) -> float:
    """Wall time [s] of one command; raises if it fails."""
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-m", "soft_snake_gym.cli", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
    )
    if res.returncode:
        raise SystemExit(f"{' '.join(args)} failed:\n{res.stderr[-2000:]}")
    return time.perf_counter() - t0


def first_cells(csv_path: Path) -> list[float]:
    """The cells' own wall times [s] in the order they were written."""
    with csv_path.open() as f:
        return [float(r["wall_time"]) for r in csv.DictReader(f)]


def main() -> None:
    """Run the measurements and print the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--skip-seeds", action="store_true", help="only the sweep and the cache")
    args = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print(f"load average before: {os.getloadavg()[0]:.1f}", flush=True)
        # the numba disk cache: a Ray worker's first cell with an empty cache, then with it warm
        cache = tmp / "numba_cache"
        grid = ["sweep", "swim-gait", "--n-alpha", "1", "--n-omega", "2", "--cycles", "1", "--no-progress"]
        for label in ("cold", "warm"):
            out = tmp / f"cache_{label}"
            wall = run(
                [*grid, "--out", str(out), "--backend", "ray", "--workers", "1"],
                {"NUMBA_CACHE_DIR": str(cache)},
            )
            cells = first_cells(out / "swim-gait.csv")
            rows.append(
                (
                    f"numba cache {label}: 4 cells, 1 Ray worker",
                    wall,
                    f"cells {', '.join(f'{c:.1f}' for c in cells)} s",
                )
            )
            print(rows[-1], flush=True)
        for backend, workers in (("local", 1), ("local", 2), ("ray", 1), ("ray", 2)):
            out = tmp / f"sweep_{backend}_{workers}"
            wall = run([*SWEEP, "--out", str(out), "--backend", backend, "--workers", str(workers)])
            rows.append((f"sweep, 32 cells, {backend} x{workers}", wall, f"load {os.getloadavg()[0]:.1f}"))
            print(rows[-1], flush=True)
        if not args.skip_seeds:
            for backend, workers in (("local", None), ("ray", 1), ("ray", 2)):
                extra = ["--backend", backend] + (["--workers", str(workers)] if workers else [])
                wall = run([*SEEDS, "--run-dir", str(tmp / f"seeds_{backend}_{workers}"), *extra])
                rows.append(
                    (
                        f"4 seeds x 4096 steps, {backend} x{workers or 1}",
                        wall,
                        f"load {os.getloadavg()[0]:.1f}",
                    )
                )
                print(rows[-1], flush=True)
    print("\n| what | wall time [s] | note |\n|---|---|---|")
    for what, wall, note in rows:
        print(f"| {what} | {wall:.0f} | {note} |")


if __name__ == "__main__":
    main()
