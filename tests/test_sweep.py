"""Parameter sweeps: a tiny grid, interrupted and resumed without recomputing finished cells."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
from support import cli_in_background

from soft_snake_gym.studies.sweep import STUDIES, StudyGrid, cell_key, read_results, run_sweep

TINY = [
    "--n-mu",
    "3",
    "--mu-min",
    "0.4",
    "--mu-max",
    "1.0",
    "--inch-duration",
    "20",
    "--workers",
    "1",
    "--no-progress",
]


def test_interrupted_sweep_resumes_without_recomputing(tmp_path):
    out = tmp_path / "sw"
    csv_path = out / "inch-friction.csv"
    # run the real command in a subprocess and kill it (SIGKILL: no clean-up at all) once two
    # cells are written
    proc = cli_in_background("sweep", "inch-friction", "--out", str(out), *TINY)
    deadline = time.time() + 120
    while time.time() < deadline and len(read_results(csv_path)) < 2 and proc.poll() is None:
        time.sleep(0.02)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the sweep finished before it could be interrupted"
    first = read_results(csv_path)
    grid = StudyGrid(n_mu=3, mu_s_min=0.4, mu_s_max=1.0, inch_duration=20.0)
    cells = STUDIES["inch-friction"].cells(grid)
    assert len(cells) == 12  # 6 (mu_d <= mu_s) x 2 controllers
    assert 2 <= len(first) < len(cells), "the interrupt should land mid-sweep"
    mtimes = {k: v["wall_time"] for k, v in first.items()}

    res = run_sweep("inch-friction", out, grid, workers=1, progress=False)
    assert res["skipped"] == len(first)
    assert res["computed"] == len(cells) - len(first)
    final = read_results(csv_path)
    assert set(final) == {cell_key(c) for c in cells}
    for key, wall in mtimes.items():  # finished rows were kept, not recomputed
        assert final[key]["wall_time"] == wall
    with csv_path.open() as f:
        assert sum(1 for _ in f) == 1 + len(cells)  # one header, each cell exactly once
    # the worm moves toward its head in every cell, and more kinetic friction costs more energy
    assert all(r["distance"] > 0.05 for r in final.values())
    e = {(r["controller"], r["mu_s"], r["mu_d"]): r["energy_friction"] for r in final.values()}
    assert e[("inching", 1.0, 1.0)] > 2 * e[("inching", 1.0, 0.4)]
    for png in ("inch-friction_distance.png", "inch-friction_energy_friction.png"):
        assert (out / png).stat().st_size > 10_000

    again = run_sweep("inch-friction", out, grid, workers=1, progress=False, figures=False)
    assert again["computed"] == 0


def test_parallel_swim_cells_match_serial(tmp_path):
    grid = StudyGrid(
        n_alpha=1, alpha_min=0.5, alpha_max=0.5, n_omega=2, omega_min=2.0, omega_max=3.0, cycles=1
    )
    par = run_sweep("swim-gait", tmp_path / "par", grid, workers=2, progress=False, figures=False)
    ser = run_sweep("swim-gait", tmp_path / "ser", grid, workers=1, progress=False, figures=False)
    assert par["computed"] == ser["computed"] == 4
    a, b = read_results(par["csv"]), read_results(ser["csv"])
    for key in a:
        assert np.isclose(a[key]["average_speed"], b[key]["average_speed"], rtol=1e-12)
        assert a[key]["failure"] == ""
    assert os.path.getsize(par["csv"]) > 0


def test_findings_count_comparisons_the_way_the_thesis_states():
    from soft_snake_gym.studies.reproduce import findings

    gait = []
    for ctrl, gain in (("open-loop", 1.0), ("pid", 1.2)):
        for a in (0.2, 0.6, 1.0):
            for w in (1.0, 2.0):
                speed = gain * w * a * (1.2 - a)  # rises with omega, peaks inside the alpha range
                gait.append(
                    {
                        "controller": ctrl,
                        "alpha": a,
                        "omega": w,
                        "average_speed": speed,
                        "curvature_error": 0.1 / gain,
                        "mean_fluid_power": gain * a * w,
                        "energy_actuator": gain * a * w,
                        "failure": "",
                    }
                )
    stiff = [
        {
            "controller": "open-loop",
            "alpha": 0.5,
            "omega": 1.0,
            "E_bend": e,
            "average_speed": s,
            "failure": "",
        }
        for e, s in ((1e4, 0.01), (1e5, 0.02), (1e6, 0.03))
    ]
    inch = [
        {
            "controller": c,
            "mu_s": ms,
            "mu_d": md,
            "distance": k * (ms - md + 1),
            "energy_friction": k * md,
            "failure": "",
        }
        for c, k in (("inching", 1.0), ("inching-pid", 2.0))
        for ms in (0.4, 0.8)
        for md in (0.4, 0.8)
        if md <= ms
    ]
    verdicts = {f["finding"]: f["verdict"] for f in findings(gait, stiff, inch)}
    assert set(verdicts.values()) == {"yes"}, verdicts
    # flip one trend and its verdict must change
    for r in stiff:
        r["average_speed"] = -r["average_speed"]
    verdicts = {f["finding"]: f["verdict"] for f in findings(gait, stiff, inch)}
    assert verdicts["Stiffer bodies swim faster open loop"] == "no"
