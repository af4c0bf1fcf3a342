"""The Ray backend on a real two-node Ray cluster, on loopback only.

The module enters a network namespace of its own whose only interface is loopback (as root,
which CI is: ``unshare(CLONE_NEWNET)``, then ``ip link set lo up``), so that every Ray address
is 127.0.0.1 and nothing listens on the machine's network. One ``ray.cluster_utils.Cluster`` of
two nodes with one CPU each serves the whole module; the commands reach it through
``--address`` from their own processes, as a user's would.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from support import TINY_TRAINING, cli, cli_in_background

pytestmark = pytest.mark.ray

SWEEP = ["swim-gait", "--n-alpha", "2", "--n-omega", "2", "--cycles", "1", "--no-progress"]
TRAIN = ["train", "SoftEel-v0", "--n-timesteps", "256", "--no-progress", "--hyperparams", *TINY_TRAINING]


@pytest.fixture(scope="module")
def cluster(ray_cluster):
    return ray_cluster


def rows(path: Path) -> dict[str, dict[str, str]]:
    """The CSV's rows by key, as written (text), without the wall time; every key once."""
    with path.open(newline="") as f:
        all_rows = list(csv.DictReader(f))
    keys = [r["key"] for r in all_rows]
    assert len(keys) == len(set(keys)), f"a cell appears twice in {path}"
    return {r["key"]: {k: v for k, v in r.items() if k != "wall_time"} for r in all_rows}


def ray_errors(out: subprocess.CompletedProcess) -> str:
    return "\n".join(line for line in out.stderr.splitlines() if "network_util" not in line)


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("local")
    res = cli("sweep", *SWEEP, "--out", str(out), "--workers", "1")
    assert res.returncode == 0, res.stderr
    return out / "swim-gait.csv"


def test_the_cluster_is_on_loopback_and_its_workers_are_set_up(cluster):
    from ray import cloudpickle

    from soft_snake_gym.distributed import connected, imap_unordered

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import tests/
    assert cluster.address.startswith("127.0.0.1:")
    with connected(cluster.address) as ray:
        nodes = [n for n in ray.nodes() if n["Alive"]]
        assert len(nodes) == 2 and {n["NodeManagerAddress"] for n in nodes} == {"127.0.0.1"}
        got = [r for _, r in imap_unordered(worker_facts, [()] * 4)]
    for facts in got:
        # threads capped to the task's one CPU; the env ids registered before any task asked
        assert facts["env"] == {v: "1" for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}
        assert facts["numba_threads"] == 1 and facts["registered"]


def worker_facts() -> dict:
    import gymnasium as gym
    import numba

    return {
        "env": {v: os.environ.get(v) for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")},
        "numba_threads": numba.get_num_threads(),
        "registered": "SoftEel-v0" in gym.registry,
    }


def test_a_sweep_on_the_cluster_writes_the_local_rows_and_resumes(cluster, local_sweep, tmp_path):
    res = cli("sweep", *SWEEP, "--out", str(tmp_path), "--backend", "ray", "--address", cluster.address)
    assert res.returncode == 0, ray_errors(res)
    assert "8 cells computed, 0 resumed" in res.stdout
    assert rows(tmp_path / "swim-gait.csv") == rows(local_sweep)  # bit for bit, in text
    # an interrupted sweep leaves the header and the rows it finished: the rest is computed
    lines = (tmp_path / "swim-gait.csv").read_text().splitlines(keepends=True)
    (tmp_path / "swim-gait.csv").write_text("".join(lines[:4]))
    res = cli("sweep", *SWEEP, "--out", str(tmp_path), "--backend", "ray", "--address", cluster.address)
    assert res.returncode == 0, ray_errors(res)
    assert "5 cells computed, 3 resumed" in res.stdout
    assert rows(tmp_path / "swim-gait.csv") == rows(local_sweep)
    res = cli("sweep", *SWEEP, "--out", str(tmp_path), "--backend", "ray", "--address", cluster.address)
    assert "0 cells computed, 8 resumed" in res.stdout  # nothing left: Ray is not even started


def test_a_local_ray_is_its_own_even_beside_a_running_cluster(cluster, local_sweep, tmp_path):
    # without --address a new Ray starts for the command, not the cluster `ray start` left
    one = ["swim-gait", "--n-alpha", "1", "--n-omega", "1", "--cycles", "1", "--no-progress"]
    res = cli("sweep", *one, "--out", str(tmp_path), "--backend", "ray", "--workers", "1")
    assert res.returncode == 0, ray_errors(res)
    got = rows(tmp_path / "swim-gait.csv")
    assert len(got) == 2 and got == {k: v for k, v in rows(local_sweep).items() if k in got}


def descendants(pid: int) -> list[int]:
    """The processes started by ``pid``, at any depth (from /proc)."""
    parent = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parent[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, frontier = [], [pid]
    while frontier:
        kids = [p for p, pp in parent.items() if pp in frontier]
        found += kids
        frontier = kids
    return found


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def test_a_killed_worker_is_retried_and_its_cell_written_once(cluster, local_sweep, tmp_path):
    sweep = cli_in_background(
        "sweep", *SWEEP, "--out", str(tmp_path), "--backend", "ray", "--address", cluster.address
    )
    killed = None
    deadline = time.time() + 300
    while killed is None and sweep.poll() is None and time.time() < deadline:
        # the cluster's processes are this test's; a worker running a cell is titled "ray::_worker"
        busy = [p for p in descendants(os.getpid()) if cmdline(p).startswith("ray::_worker")]
        if busy:
            os.kill(busy[0], signal.SIGKILL)
            killed = busy[0]
        time.sleep(0.02)
    out, err = sweep.communicate(timeout=600)
    assert killed is not None, "no worker was caught running a cell"
    assert sweep.returncode == 0, err
    assert "8 cells computed" in out
    assert killed not in descendants(os.getpid()) or "ray::_worker" not in cmdline(killed)
    assert rows(tmp_path / "swim-gait.csv") == rows(local_sweep)  # each cell once, as a clean run's


@pytest.fixture(scope="module")
def seed_runs(cluster, tmp_path_factory) -> tuple[Path, Path]:
    """Seeds 0-1 trained locally and on the cluster; seeds 2-3 added locally to the cluster's."""
    base = tmp_path_factory.mktemp("seeds")
    res = cli(*TRAIN, "--seeds", "0-1", "--run-dir", str(base / "local"))
    assert res.returncode == 0, res.stderr
    res = cli(
        *TRAIN,
        "--seeds",
        "0-1",
        "--run-dir",
        str(base / "ray"),
        "--backend",
        "ray",
        "--address",
        cluster.address,
    )
    assert res.returncode == 0, ray_errors(res)
    assert "seeds 0-1 (2 runs, on Ray" in res.stdout
    return base / "local", base / "ray"


def curve(run: Path) -> list[dict[str, str]]:
    with (run / "learning_curve.csv").open() as f:
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)]


def test_seeds_trained_on_the_cluster_equal_the_local_runs(seed_runs):
    local, on_ray = seed_runs
    for seed in (0, 1):
        run, ref = on_ray / f"s{seed}", local / f"s{seed}"
        files = sorted(str(p.relative_to(run)) for p in run.rglob("*") if "tb" not in p.parts)
        assert files == sorted(str(p.relative_to(ref)) for p in ref.rglob("*") if "tb" not in p.parts)
        for name in (
            "config.yaml",
            "final_model.zip",
            "best_model.zip",
            "vecnormalize.pkl",
            "learning_curve.csv",
        ):
            assert name in files
        assert "checkpoints/model_256_steps.zip" in files and any((run / "tb").iterdir())
        assert curve(run) == curve(ref)  # same seed, same training, bit for bit
    assert curve(on_ray / "s0") != curve(on_ray / "s1")  # and the seeds differ


def test_compare_over_four_seeds_reports_rliables_iqm_and_interval(seed_runs, tmp_path):
    from rliable import library, metrics

    from soft_snake_gym.studies.compare import BOOTSTRAP_REPS, BOOTSTRAP_SEED

    _, parent = seed_runs
    res = cli(*TRAIN, "--seeds", "2-3", "--run-dir", str(parent))  # seeds 2, 3 beside the Ray ones
    assert res.returncode == 0, res.stderr
    runs = [str(parent / f"s{s}") for s in range(4)]
    out = tmp_path / "c.json"
    res = cli(
        "compare", "SoftEel-v0", "--policies", "pid", str(parent), runs[0],
        "--episodes", "1", "--out", str(tmp_path / "c.png"), "--json", str(out),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    per_run = doc["seed_sets"][str(parent)]
    assert list(per_run) == runs
    for key in ("average_speed", "return", "energy_actuator"):
        scores = np.array([per_run[r][key] for r in runs])
        assert per_run[runs[0]][key] == doc["results"][runs[0]][key][0]  # as that run on its own
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # arch's random_state deprecation
            point, interval = library.get_interval_estimates(
                {key: scores.reshape(-1, 1)},
                lambda x: np.array([metrics.aggregate_iqm(x)]),
                reps=BOOTSTRAP_REPS,
                random_state=np.random.RandomState(BOOTSTRAP_SEED),
            )
        iqm, lo, hi = doc["results"][str(parent)][key]
        assert (iqm, lo, hi) == (point[key][0], interval[key][0, 0], interval[key][1, 0])
        assert math.isclose(iqm, np.sort(scores)[1:3].mean(), rel_tol=1e-12)  # IQM of 4 = middle two
        assert lo <= iqm <= hi and lo < hi
        assert f"{iqm:.4g} [{lo:.4g}, {hi:.4g}]" in res.stdout
    assert "interquartile mean" in res.stdout and (tmp_path / "c.png").is_file()


def test_an_unreachable_address_is_one_line_fast_and_writes_nothing(cluster, tmp_path):
    t0 = time.time()
    res = cli("sweep", *SWEEP, "--out", str(tmp_path / "s"), "--backend", "ray", "--address", "127.0.0.1:9")
    assert time.time() - t0 < 60
    assert res.returncode == 2 and ray_errors(res).count("\n") == 0
    assert "'127.0.0.1:9'" in res.stderr and "ray start --head" in res.stderr
    assert not (tmp_path / "s" / "swim-gait.csv").exists()
    res = cli(
        *TRAIN, "--seeds", "0-1", "--run-dir", str(tmp_path / "t"), "--backend", "ray", "--address", "nowhere"
    )
    assert res.returncode == 2 and "'nowhere' is not host:port" in res.stderr
    assert not (tmp_path / "t").exists()


def test_bad_seed_ranges_are_one_line_errors(tmp_path):
    for seeds, expected in (
        ("5-2", "the range 5-2 ends below its start; write 2-5"),
        ("a-b", "'a-b' is not a seed or a range; write e.g. 0-7 or 0,2,5"),
        ("0-2,1", "names seed 1 twice"),
    ):
        res = cli(*TRAIN, "--seeds", seeds, "--run-dir", str(tmp_path / "r"))
        assert res.returncode == 2, res.stderr
        assert res.stderr.strip() == f"soft-snake train: error: --seeds {seeds!r}: {expected}"
    assert not (tmp_path / "r").exists()
    res = cli(*TRAIN, "--backend", "ray")
    assert res.returncode == 2 and "add e.g. --seeds 0-3" in res.stderr
    res = cli("sweep", *SWEEP, "--address", "auto")
    assert res.returncode == 2 and "--address auto needs --backend ray" in res.stderr


@pytest.mark.parametrize(
    "missing, args",
    [
        ("ray", ["sweep", *SWEEP, "--backend", "ray"]),
        ("ray", [*TRAIN, "--seeds", "0-1", "--backend", "ray"]),
        ("rliable", ["compare", "SoftEel-v0", "--policies", "SEEDS", "--episodes", "1"]),
    ],
)
def test_the_ray_backend_without_its_extra_names_the_install_line(missing, args, seed_runs, tmp_path):
    args = [str(seed_runs[1]) if a == "SEEDS" else a for a in args]
    args += (
        ["--out", str(tmp_path / ("c.png" if args[0] == "compare" else "o"))] if args[0] != "train" else []
    )
    code = (
        f"import sys; sys.modules[{missing!r}] = None; from soft_snake_gym.cli import main; "
        f"sys.exit(main({args!r}))"
    )  # the package absent (import fails), not a stand-in for it
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and 'pip install "soft-snake-gym[ray]"' in res.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "runs").exists()
