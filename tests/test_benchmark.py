"""``soft-snake benchmark`` writes its tables, JSON and figure; the numba cache guard works."""

from __future__ import annotations

import json
import subprocess
import sys

from soft_snake_gym.cli import main
from soft_snake_gym.physics.cache import drop_stale_cache


def test_benchmark_cli_writes_json_and_png(tmp_path, capsys):
    out = tmp_path / "bench.json"
    code = main(
        [
            "benchmark",
            "--seconds",
            "0.05",
            "--repeats",
            "1",
            "--robots",
            "2",
            "--no-ppo",
            "--nodes",
            "10",
            "12",
            "--node-robots",
            "2",
            "--json",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0
    res = json.loads(out.read_text())
    assert (tmp_path / "bench.png").stat().st_size > 10_000
    cases = [r["case"] for r in res["throughput"]]
    assert cases[:3] == ["SoftEel-v0 gym.make", "SoftWorm-v0 gym.make", "SoftEel-v0 batched n=2 threads=1"]
    assert all(r["steps_per_s"] > 0 for r in res["throughput"])
    assert [r["N"] for r in res["nodes"]] == [10, 12]
    assert 0 < res["kernel_share"]["SoftEel-v0 batched n=2 threads=1"] < 1
    text = capsys.readouterr().out
    assert "targets (ratios measured in this run)" in text and str(out) in text
    if res["mujoco"] == "installed":
        assert "Swimmer-v5 gym.make" in cases
        assert res["ratios"]["single_vs_swimmer"] > 0 and res["ratios"]["worm_single_vs_swimmer"] > 0
    else:
        assert "Swimmer-v5 rows skipped" in text


def test_benchmark_rejects_bad_options(capsys):
    assert main(["benchmark", "--robots", "0", "--no-ppo"]) == 2
    assert "robot counts must be >= 1" in capsys.readouterr().err


def test_stale_numba_cache_is_dropped_when_a_dependency_changes(tmp_path):
    module = tmp_path / "caller.py"
    dep = tmp_path / "callee.py"
    module.write_text("# caller")
    dep.write_text("x = 1")
    cache = tmp_path / "__pycache__"
    assert drop_stale_cache(str(module), [str(dep)])  # first sight: recorded
    cached = [cache / "caller.f-10.py311.nbi", cache / "caller.f-10.py311.1.nbc"]
    other = cache / "callee.g-3.py311.nbi"
    for f in cached + [other]:
        f.write_text("machine code")
    assert not drop_stale_cache(str(module), [str(dep)])  # unchanged: kept
    assert all(f.exists() for f in cached)
    dep.write_text("x = 2")
    assert drop_stale_cache(str(module), [str(dep)])  # changed: the caller's cache goes
    assert not any(f.exists() for f in cached) and other.exists()


def test_ppo_timing_runs_from_the_command_line_with_subprocess_workers(tmp_path):
    # `python -m soft_snake_gym.cli` runs a package __main__, which multiprocessing does not
    # re-import in SubprocVecEnv's workers: they must make the ids all the same
    out = tmp_path / "bench.json"
    args = ["--seconds", "0.05", "--repeats", "1", "--robots", "2", "--nodes", "--ppo-timesteps", "512"]
    proc = subprocess.run(
        [sys.executable, "-m", "soft_snake_gym.cli", "benchmark", *args, "--json", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    ppo = {r["kind"]: r for r in json.loads(out.read_text())["ppo"]}
    assert set(ppo) == {"batched", "subproc"}
    assert all(r["steps_per_s"] > 0 for r in ppo.values())
