"""``soft-snake benchmark`` writes its tables, JSON and figure; the numba cache guard works."""

from __future__ import annotations

import json
import signal
import statistics
import sys
from pathlib import Path

import pytest
from support import cli, cli_in_background

from soft_snake_gym import benchmark
from soft_snake_gym.benchmark import format_report, run_benchmark
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
            "--envpool-robots",
            "3",
            "--json",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0
    res = json.loads(out.read_text())
    assert (tmp_path / "bench.png").stat().st_size > 10_000
    cases = [r["case"] for r in res["throughput"]]
    assert cases[:4] == [
        "SoftEel-v0 gym.make",
        "SoftWorm-v0 gym.make",
        "SoftEel-v0 batched n=2 threads=1",
        "SoftWorm-v0 batched n=2 threads=1",
    ]
    assert all(r["steps_per_s"] > 0 for r in res["throughput"])
    # simulated time per wall second is steps/s times each env's own control step
    dts = {r["case"].split()[0]: r["dt"] for r in res["throughput"]}
    assert dts["SoftEel-v0"] == dts["SoftWorm-v0"] == 0.01
    for r in res["throughput"]:
        assert abs(r["sim_s_per_s"] - r["steps_per_s"] * r["dt"]) < 1e-9 * r["sim_s_per_s"]
    assert [r["N"] for r in res["nodes"]] == [10, 12]
    assert 0 < res["kernel_share"]["SoftEel-v0 batched n=2 threads=1"] < 1
    # the peak is a real matrix product (any machine's BLAS makes more than 1 GFLOP/s on a core);
    # our plain rows' work is steps/s x the counted flops, against the peak on their threads
    assert res["peak"]["gflops"]["1"] > 1.0
    compute = {r["case"]: r for r in res["compute"]}
    assert sorted(compute) == sorted(cases[:4])
    for case, flops in (("SoftEel-v0 batched n=2 threads=1", 27_600), ("SoftWorm-v0 gym.make", 27_500)):
        row, steps = compute[case], next(r["steps_per_s"] for r in res["throughput"] if r["case"] == case)
        assert row["flops_per_step"] == flops
        assert abs(row["fraction_of_peak"] - steps * flops / 1e9 / res["peak"]["gflops"]["1"]) < 1e-12
    text = capsys.readouterr().out
    assert "targets (ratios measured in this run" in text and str(out) in text
    cpuinfo = Path("/proc/cpuinfo")
    models = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    models = [line.split(":", 1)[1].strip() for line in models if line.startswith("model name")]
    if models:  # the run names its CPU, as Linux does
        assert res["machine"]["processor"] == models[0]
        assert models[0] in text.splitlines()[0]
    assert "floating-point work against the machine's peak" in text
    # what numba compiled for, as its code generator says
    from numba.core.registry import cpu_target

    llvm_cpu = cpu_target.target_context.codegen().magic_tuple()[1]
    assert res["machine"]["llvm_cpu"] == llvm_cpu and f"code for LLVM's {llvm_cpu}" in text.splitlines()[0]
    if res["mujoco"] == "installed":
        assert "Swimmer-v5 gym.make" in cases
        assert res["ratios"]["single_vs_swimmer"] > 0 and res["ratios"]["worm_single_vs_swimmer"] > 0
        assert dts["Swimmer-v5"] == 0.04
    else:
        assert "Swimmer-v5 rows skipped" in text
    if res["envpool"] == "installed":
        pool = [r for r in res["throughput"] if r["case"].startswith("EnvPool Swimmer-v4")]
        assert [r["robots"] for r in pool] == [1, 3]
        assert all(abs(r["dt"] - 0.04) < 1e-12 for r in pool)  # frame_skip 4 x timestep 0.01
    else:
        assert "EnvPool Swimmer-v4 rows skipped" in text


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_benchmark_writes_its_complete_rounds_and_exits_with_the_signal(tmp_path, sig):
    out = tmp_path / "bench.json"
    run = cli_in_background(
        *["benchmark", "--seconds", "0.02", "--repeats", "1000", "--robots", "2", "--no-ppo"],
        *["--nodes", "10", "--node-robots", "2", "--envpool-robots", "2", "--json", str(out)],
    )
    for line in run.stderr:  # the third round begins: two are complete
        if "round 3/1000" in line:
            break
    run.send_signal(sig)
    stdout, stderr = run.communicate(timeout=300)
    assert run.returncode == 128 + sig, stderr
    res = json.loads(out.read_text())
    stop = res["interrupted"]
    assert stop["signal"] == signal.Signals(sig).name
    rounds = {len(r["rounds"]) for r in res["throughput"]} | {len(v) for v in res["peak"]["rounds"].values()}
    assert len(rounds) == 1  # every case keeps the same rounds, the complete ones
    (complete,) = rounds
    assert 2 <= complete < 1000
    assert stop["where"] == f"in round {complete + 1} of 1000; its {complete} complete rounds are kept"
    for r in res["throughput"]:  # each figure is the median of the rounds kept
        assert r["steps_per_s"] == statistics.median(r["rounds"]) > 0
    assert res["nodes"] == [] and res["kernel_share"] == {}  # the phases after the rounds did not run
    assert f"stopped early by {stop['signal']} {stop['where']}" in stdout
    assert (tmp_path / "bench.png").stat().st_size > 10_000


def test_a_benchmark_stopped_in_its_first_round_writes_nothing_and_says_why(tmp_path):
    out = tmp_path / "bench.json"
    run = cli_in_background(
        *["benchmark", "--seconds", "5", "--repeats", "2", "--robots", "2", "--no-ppo", "--nodes"],
        *["--json", str(out)],
    )
    for line in run.stderr:
        if "round 1/2" in line:
            break
    run.send_signal(signal.SIGTERM)
    _, stderr = run.communicate(timeout=300)
    assert run.returncode == 143, stderr
    assert "stopped by SIGTERM before every case had run once; nothing written" in stderr
    assert not out.exists()


def test_benchmark_warms_up_every_case_and_without_envpool_skips_its_rows(monkeypatch):
    monkeypatch.setitem(sys.modules, "envpool", None)  # as if not installed: import raises
    said = []
    res = run_benchmark(seconds=0.02, repeats=1, robots=(2,), ppo=False, nodes=(), progress=said.append)
    assert not any(r["case"].startswith("EnvPool") for r in res["throughput"])
    # every measured case stepped unmeasured before the first round (numba's code loaded then)
    first_round = next(k for k, msg in enumerate(said) if msg.startswith("round 1/"))
    warmed = {
        msg.removeprefix("warming up: ") for msg in said[:first_round] if msg.startswith("warming up: ")
    }
    assert warmed == {r["case"] for r in res["throughput"]}
    assert "pip install 'soft-snake-gym[bench]'" in res["envpool"]
    assert "EnvPool Swimmer-v4 rows skipped" in format_report(res)


def test_benchmark_rejects_bad_options(capsys, tmp_path):
    assert main(["benchmark", "--robots", "0", "--no-ppo"]) == 2
    assert "robot counts must be >= 1" in capsys.readouterr().err
    # output paths that could not be written are refused before the run, not after it
    assert main(["benchmark", "--json", str(tmp_path)]) == 2
    assert "is a folder; give a file name" in capsys.readouterr().err
    assert main(["benchmark", "--json", str(tmp_path / "b.json"), "--png", str(tmp_path / "b.xyz")]) == 2
    err = capsys.readouterr().err
    assert "--png: cannot draw a chart into" in err and ".png" in err
    assert not list(tmp_path.iterdir())


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


def test_ppo_timing_runs_from_the_command_line_with_subprocess_workers(tmp_path, monkeypatch):
    # `python -m soft_snake_gym.cli` runs a package __main__, which multiprocessing does not
    # re-import in SubprocVecEnv's workers: they must make the ids all the same
    out = tmp_path / "bench.json"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))  # the command's temporary directory, inherited
    args = ["--seconds", "0.05", "--repeats", "2", "--robots", "2", "--nodes", "--ppo-timesteps", "512"]
    proc = cli("benchmark", *args, "--ppo-n-envs", "2", "--json", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    ppo = {r["kind"]: r for r in json.loads(out.read_text())["ppo"]}
    assert set(ppo) == {"batched", "subproc"}
    # interleaved rounds of one rollout each (512 steps x 2 envs), the median reported
    for r in ppo.values():
        assert r["n_envs"] == 2 and r["timesteps"] == 2 * 1024 and len(r["rounds"]) == 2
        assert min(r["rounds"]) > 0 and r["steps_per_s"] == statistics.median(r["rounds"])
    # the batched env's three training-throughput figures: stepping >= + inference, both > 0
    b = ppo["batched"]
    assert b["step_steps_per_s"] > 0 and b["inference_steps_per_s"] > 0
    # and our env's step alone, without VecNormalize's statistics over the observations
    assert b["env_steps_per_s"] > b["step_steps_per_s"]
    # a timing run leaves no logs behind (SB3's default logger makes /tmp/SB3-<date> per learn())
    assert not list(tmp.glob("SB3-*"))


def test_targets_are_read_off_the_default_rows_and_the_variants_are_reported_beside_them():
    def row(case, steps, dt=0.01):
        return {
            "case": case,
            "steps_per_s": steps,
            "sim_s_per_s": steps * dt,
            "dt": dt,
            "rounds": [steps] * 3,
        }

    res = {
        "throughput": [
            row("SoftEel-v0 batched n=256 threads=1", 30_000),
            row("SoftEel-v0 batched n=256 threads=2", 60_000),
            row("SoftEel-v0 batched n=256 threads=1, gait actions", 90_000),
            row("SoftEel-v0 batched n=256 threads=2, bdf2", 80_000),
            row("Swimmer-v5 gym.make", 10_000, 0.04),
            row("EnvPool Swimmer-v4 n=256 threads=2", 20_000, 0.04),
        ],
        "ppo": [],
        "nodes": [],
    }
    r = benchmark._ratios(res)
    assert r["batched256_case"] == "SoftEel-v0 batched n=256 threads=2"
    assert r["batched256_vs_swimmer"] == pytest.approx(1.5) and r["batched256_vs_envpool"] == pytest.approx(
        0.75
    )
    assert r["batched256_gait_vs_swimmer"] == pytest.approx(2.25)
    assert r["batched256_bdf2_vs_swimmer"] == pytest.approx(2.0)
    assert r["batched256_bdf2_vs_envpool"] == pytest.approx(1.0)


def test_each_target_is_given_round_by_round_beside_the_ratio_of_the_medians():
    def row(case, rounds, dt):
        return {"case": case, "steps_per_s": statistics.median(rounds), "dt": dt, "rounds": rounds,
                "sim_s_per_s": statistics.median(rounds) * dt}  # fmt: skip

    res = {
        "throughput": [
            row("SoftWorm-v0 gym.make", [30_000, 36_000, 21_000], 0.01),
            row("SoftWorm-v0 batched n=256 threads=2", [50_000, 60_000, 70_000], 0.01),
            row("Swimmer-v5 gym.make", [10_000, 12_000, 7_000], 0.04),
        ],
        "ppo": [
            {
                "kind": "batched",
                "n_envs": 8,
                "steps_per_s": 400,
                "rounds": [400, 300, 500],
                "env_steps_per_s": 1600,
            },
            {"kind": "subproc", "n_envs": 8, "steps_per_s": 200, "rounds": [100, 200, 250]},
        ],
        "nodes": [],
    }
    r = benchmark._ratios(res)
    # round i of one case against round i of the other: the machine's speed in that pass cancels
    assert r["worm_single_vs_swimmer"] == pytest.approx(3.0)  # the medians' ratio decides the verdict
    assert r["worm_single_vs_swimmer_rounds"] == pytest.approx([3.0, 3.0, 3.0])
    assert r["worm256_vs_swimmer"] == pytest.approx(600 / 400)  # in simulated seconds
    assert r["worm256_vs_swimmer_rounds"] == pytest.approx([500 / 400, 600 / 480, 700 / 280])
    assert r["ppo_batched_vs_subproc_rounds"] == pytest.approx([4.0, 1.5, 2.0])
    # 2.5 ms a batched step, 0.625 ms of it our env's: the subprocesses' 5 ms against the 1.875 left
    assert r["ppo_env_free_bound"] == pytest.approx(5.0 / 1.875)
    res["machine"] = {"platform": "test", "cpus": 2, "numba_threads": 2, "threading_layer": "omp"}
    res["kernel_share"] = {}
    text = format_report({**res, "ratios": r})
    assert "rounds 1.25x to 2.50x)" in text  # every round under the worms' 10x line
    assert "rounds 1.50x to 4.00x, on both sides of the line)" in text  # PPO's 2x: a noisy verdict
    assert "(with our env's step free: 2.67x;" in text
    assert "rounds 3.00x to 3.00x)" in text  # the single worm's rounds all on its 3x line: met
    assert "against the machine's peak" not in text  # results from before the peak was measured
    # the work of our plain rows (not the Swimmer's) against the peak on each row's threads
    res["peak"] = {"gflops": {"1": 10.0, "2": 20.0}}
    compute = {c["case"]: c for c in benchmark._compute(res)}
    assert sorted(compute) == ["SoftWorm-v0 batched n=256 threads=2", "SoftWorm-v0 gym.make"]
    assert compute["SoftWorm-v0 gym.make"]["gflops"] == pytest.approx(30_000 * 27_500 / 1e9)
    assert compute["SoftWorm-v0 batched n=256 threads=2"]["fraction_of_peak"] == pytest.approx(
        60_000 * 27_500 / 1e9 / 20.0
    )
    text = format_report({**res, "ratios": r, "compute": list(compute.values())})
    assert "10.0 GFLOP/s on 1 thread(s), 20.0 GFLOP/s on 2 thread(s)" in text
    assert "SoftWorm-v0 batched n=256 threads=2" in text and "8.2 %" in text
